// The parameter form. Every control carries `data-field` (a path into SessionParams, as the
// server names fields in its errors) and `data-kind`; a change sends a JSON merge patch of
// that one field, and the server's answer (an `updated` event or an error naming the field)
// is what the form shows.

/** The value at `path` (dot-separated) of `object`. */
export function valueAt(object, path) {
  return path.split('.').reduce((o, key) => (o === null || o === undefined ? undefined : o[key]), object);
}

/** A merge patch that sets `path` to `value`. */
export function patchFor(path, value) {
  return path.split('.').reduceRight((inner, key) => ({ [key]: inner }), value);
}

function read(control) {
  const raw = control.type === 'checkbox' ? control.checked : control.value.trim();
  switch (control.dataset.kind) {
    case 'bool':
      return { value: raw };
    case 'int':
      return /^-?\d+$/.test(raw) ? { value: Number(raw) } : { error: 'enter a whole number' };
    case 'float':
      return raw !== '' && Number.isFinite(Number(raw)) ? { value: Number(raw) } : { error: 'enter a number' };
    case 'optional-int':
      if (raw === '') return { value: null };
      return /^\d+$/.test(raw) ? { value: Number(raw) } : { error: 'enter a whole number, or leave it empty' };
    case 'optional-float':
      if (raw === '') return { value: null };
      return Number.isFinite(Number(raw)) ? { value: Number(raw) } : { error: 'enter a number, or leave it empty' };
    case 'environment-kind':
      // `render.environment` as a whole: none removes it, a kind merges into what it was.
      return { value: raw === 'none' ? null : { kind: raw } };
    default:
      return { value: raw };
  }
}

/** The form's `data-kind` of a parameter kind of `/v1/server`'s `gi_methods`. */
const KINDS = { integer: 'int', number: 'float', boolean: 'bool', optional_number: 'optional-float' };

export class Panel {
  constructor(root, onPatch) {
    this.root = root;
    this.onPatch = onPatch;
    this.controls = [];
    this.outputs = new Map([...root.querySelectorAll('[data-output-for]')].map((o) => [o.dataset.outputFor, o]));
    /** Per GI method: the names of the parameters it reads. */
    this.methodParams = new Map();
    /** Per GI method: the debug views it draws (besides `final`). */
    this.methodViews = new Map();
    this.summaries = new Map();
    for (const control of root.querySelectorAll('[data-field]')) this.wire(control);
  }

  wire(control) {
    this.controls.push(control);
    control.addEventListener('input', () => this.showOutput(control));
    control.addEventListener('change', () => {
      const { value, error } = read(control);
      if (error) {
        this.markError(control.dataset.field, error);
        return;
      }
      const patch = patchFor(control.dataset.field, value);
      // A method that does not draw the current debug view switches back to the final frame
      // (the server would refuse the method with that view).
      const view = this.control('render.view');
      if (control.dataset.field === 'render.gi.method' && view && view.value !== 'final'
          && !(this.methodViews.get(value) || new Set()).has(view.value)) {
        patch.render.view = 'final';
      }
      this.onPatch(patch, control.dataset.field);
    });
  }

  control(field) {
    return this.controls.find((c) => c.dataset.field === field);
  }

  /** Sets ranges from the server's limits (`GET /v1/server`). */
  applyLimits(limits) {
    this.control('fps_cap').max = limits.max_fps;
  }

  /**
   * Builds the method list, every method's parameter controls and the view menu from the
   * server's description (`gi_methods` of `GET /v1/server`); only the current method's
   * parameters are shown and only its views can be picked.
   */
  applyGiMethods(methods) {
    const select = this.control('render.gi.method');
    select.replaceChildren(...methods.map((m) => {
      const option = new Option(m.method, m.method);
      option.title = m.summary;
      return option;
    }));
    const container = this.root.querySelector('#gi-params');
    const built = new Map();
    for (const m of methods) {
      this.summaries.set(m.method, m.summary);
      this.methodParams.set(m.method, new Set(m.parameters.map((p) => p.name)));
      for (const p of m.parameters) {
        if (built.has(p.name)) continue;
        const label = document.createElement('label');
        label.dataset.giParam = p.name;
        label.title = p.unit ? `${p.description} (${p.unit})` : p.description;
        const control = document.createElement(p.kind === 'choice' ? 'select' : 'input');
        control.dataset.field = `render.gi.${p.name}`;
        control.dataset.kind = KINDS[p.kind] || 'string';
        if (p.kind === 'choice') {
          control.append(...(p.choices || []).map((c) => new Option(c, c)));
          label.append(`${p.name} `, control);
        } else if (p.kind === 'boolean') {
          control.type = 'checkbox';
          label.className = 'inline';
          label.append(control, ` ${p.name}`);
        } else {
          control.type = 'number';
          control.step = p.kind === 'integer' ? '1' : 'any';
          // An open end (`min_exclusive`: the bound itself is refused) is left to the server.
          if (p.min !== undefined && !p.min_exclusive) control.min = String(p.min);
          if (p.max !== undefined && !p.max_exclusive) control.max = String(p.max);
          if (p.default === null) control.placeholder = 'default';
          label.append(`${p.name} `, control);
        }
        container.append(label);
        built.set(p.name, label);
        this.wire(control);
      }
    }
    this.giParamLabels = built;
    const views = this.control('render.view');
    const listed = new Set([...views.options].map((o) => o.value));
    for (const m of methods) {
      this.methodViews.set(m.method, new Set((m.views || []).map((v) => v.view)));
      for (const v of m.views || []) {
        if (listed.has(v.view)) continue;
        const option = new Option(v.view, v.view);
        option.title = v.summary;
        views.append(option);
        listed.add(v.view);
      }
    }
  }

  /** Offers only the stream codecs both the server and this page handle. */
  applyCodecs(codecs) {
    const select = this.control('encoding.codec');
    for (const option of select.options) {
      option.disabled = !codecs.includes(option.value);
      option.title = option.disabled ? 'not available: the server does not encode it, or this browser cannot decode it' : '';
    }
  }

  /** Shows the parameters of `method` and hides the others'; offers only its views. */
  showMethod(method) {
    const names = this.methodParams.get(method) || new Set();
    for (const [name, label] of this.giParamLabels || []) label.hidden = !names.has(name);
    const views = this.methodViews.get(method) || new Set();
    for (const option of this.control('render.view').options) {
      option.disabled = option.value !== 'final' && !views.has(option.value);
    }
    const summary = this.root.querySelector('#gi-method-summary');
    if (summary) summary.textContent = this.summaries.get(method) || '';
  }

  /** Shows the session's parameters, leaving alone a control that is being edited. */
  show(params) {
    const method = valueAt(params, 'render.gi.method');
    if (method) this.showMethod(method);
    const environment = valueAt(params, 'render.environment');
    const environmentControls = this.root.querySelector('#environment-controls');
    if (environmentControls) environmentControls.hidden = !environment;
    const turbidity = this.root.querySelector('#environment-turbidity');
    if (turbidity) turbidity.hidden = environment?.kind !== 'sky';
    for (const control of this.controls) {
      if (document.activeElement === control && control.type === 'number') continue;
      let value = valueAt(params, control.dataset.field);
      if (control.dataset.kind === 'environment-kind') value = value ? value.kind : 'none';
      if (control.type === 'checkbox') {
        // `null` leaves the choice to the server (e.g. `emitters`: by the light in use).
        control.indeterminate = value === null || value === undefined;
        control.checked = Boolean(value);
      } else if (control.tagName === 'SELECT' && value !== undefined && ![...control.options].some((o) => o.value === String(value))) {
        control.append(new Option(String(value), String(value)));
        control.value = String(value);
      } else {
        control.value = value === null || value === undefined ? '' : String(value);
      }
      this.showOutput(control);
    }
  }

  showOutput(control) {
    const output = this.outputs.get(control.dataset.field);
    if (output) output.textContent = control.value;
  }

  /**
   * Marks the control of `field` (a server field path, possibly longer or prefixed), else the
   * control of the object it is in (`render.environment.kind`: the environment's menu).
   */
  markError(field, message) {
    const control = this.controls.find((c) => field === c.dataset.field || field.endsWith(`.${c.dataset.field}`))
      || this.controls.find((c) => field.startsWith(`${c.dataset.field}.`));
    if (!control) return false;
    control.classList.add('invalid');
    control.title = message;
    return true;
  }

  clearErrors() {
    for (const control of this.controls) {
      control.classList.remove('invalid');
      control.removeAttribute('title');
    }
  }
}
