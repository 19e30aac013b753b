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
    case 'optional-float':
      if (raw === '') return { value: null };
      return Number.isFinite(Number(raw)) ? { value: Number(raw) } : { error: 'enter a number, or leave it empty' };
    default:
      return { value: raw };
  }
}

export class Panel {
  constructor(root, onPatch) {
    this.controls = [...root.querySelectorAll('[data-field]')];
    this.outputs = new Map([...root.querySelectorAll('[data-output-for]')].map((o) => [o.dataset.outputFor, o]));
    for (const control of this.controls) {
      control.addEventListener('input', () => this.showOutput(control));
      control.addEventListener('change', () => {
        const { value, error } = read(control);
        if (error) {
          this.markError(control.dataset.field, error);
          return;
        }
        onPatch(patchFor(control.dataset.field, value), control.dataset.field);
      });
    }
  }

  control(field) {
    return this.controls.find((c) => c.dataset.field === field);
  }

  /** Sets ranges from the server's limits (`GET /v1/server`). */
  applyLimits(limits) {
    const rsm = this.control('render.gi.rsm_size');
    const sizes = [];
    for (let s = 64; s <= limits.max_rsm_size; s *= 2) sizes.push(s);
    rsm.replaceChildren(...sizes.map((s) => new Option(`${s}²`, String(s))));
    this.control('render.gi.view_samples').max = limits.max_view_samples;
    this.control('render.gi.val_count').max = limits.max_val_count;
    this.control('fps_cap').max = limits.max_fps;
  }

  /** Shows the session's parameters, leaving alone a control that is being edited. */
  show(params) {
    for (const control of this.controls) {
      if (document.activeElement === control && control.type === 'number') continue;
      const value = valueAt(params, control.dataset.field);
      if (control.type === 'checkbox') {
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

  /** Marks the control of `field` (a server field path, possibly longer or prefixed). */
  markError(field, message) {
    const control = this.controls.find((c) => field === c.dataset.field || field.endsWith(`.${c.dataset.field}`));
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
