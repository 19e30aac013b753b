// The offline API page (`/api`): renders this server's own openapi.json and asyncapi.json.
// Everything comes from the server itself, so it works without network access.

import { ApiError, getJson, setToken, takeTokenFromFragment } from './api.js';

/** An element with attributes and children (strings become text, never HTML). */
function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  for (const c of children.flat()) {
    if (c !== null && c !== undefined) e.append(c instanceof Node ? c : String(c));
  }
  return e;
}

const refName = (ref) => ref.split('/').pop();
const schemaLink = (name) => el('a', { href: `#schema-${name}`, class: 'type' }, name);

/** A schema's type in one line, with links to named types. */
function typeOf(s) {
  if (!s) return '';
  if (s.$ref) return schemaLink(refName(s.$ref));
  const variants = s.oneOf || s.anyOf;
  if (variants) return joined(variants.map(typeOf), ' | ');
  if (s.enum) return el('span', { class: 'type' }, s.enum.map((v) => JSON.stringify(v)).join(' | '));
  if (s.const !== undefined) return el('span', { class: 'type' }, JSON.stringify(s.const));
  if (s.type === 'array') return el('span', {}, typeOf(s.items), '[]');
  const types = [].concat(s.type || 'any');
  const text = types.join(' | ') + (s.format ? ` (${s.format})` : '');
  return el('span', { class: 'type' }, text);
}

function joined(nodes, separator) {
  const span = el('span');
  nodes.forEach((n, i) => span.append(...(i ? [separator, n] : [n])));
  return span;
}

function propertiesTable(s) {
  const required = new Set(s.required || []);
  const rows = Object.entries(s.properties || {}).map(([name, p]) =>
    el('tr', {}, el('td', {}, el('code', {}, name)), el('td', {}, typeOf(p)),
      el('td', {}, required.has(name) ? 'required' : ''), el('td', {}, p.description || '')));
  if (!rows.length) return null;
  return el('table', {}, el('tr', {}, el('th', {}, 'field'), el('th', {}, 'type'), el('th'),
    el('th', {}, 'meaning')), rows);
}

function renderSchema(name, s) {
  const variants = s.oneOf || s.anyOf || [];
  return el('div', { class: 'schema', id: `schema-${name}` },
    el('h3', {}, el('code', {}, name), ' ', el('span', { class: 'muted' },
      s.oneOf || s.anyOf ? `one of ${(s.oneOf || s.anyOf).length}:` : typeOf(s))),
    s.description ? el('p', {}, s.description) : null,
    propertiesTable(s),
    variants.map((v) => el('div', {}, el('p', {}, typeOf(v.properties ? { type: 'object' } : v), ' ',
      v.description || ''), propertiesTable(v))));
}

function contentTypes(content) {
  return Object.entries(content || {}).map(([type, c]) =>
    el('div', {}, el('code', {}, type), c.schema ? [' ', typeOf(c.schema)] : null));
}

function renderOperation(path, method, op) {
  const params = (op.parameters || []).map((p) =>
    el('tr', {}, el('td', {}, el('code', {}, p.name)), el('td', {}, p.in),
      el('td', {}, typeOf(p.schema)), el('td', {}, p.description || '')));
  const responses = Object.entries(op.responses || {}).map(([status, r]) =>
    el('tr', {}, el('td', {}, status), el('td', {}, r.description || ''), el('td', {}, contentTypes(r.content))));
  return el('details', { id: `op-${method}-${path}` },
    el('summary', {}, el('span', { class: 'method' }, method), ' ', el('span', { class: 'path' }, path),
      op.summary ? el('span', { class: 'muted' }, ` — ${op.summary}`) : null),
    op.description ? el('p', {}, op.description) : null,
    params.length ? el('table', {}, el('tr', {}, el('th', {}, 'parameter'), el('th', {}, 'in'),
      el('th', {}, 'type'), el('th', {}, 'meaning')), params) : null,
    op.requestBody ? el('div', {}, el('b', {}, 'Body: '), contentTypes(op.requestBody.content)) : null,
    el('table', {}, el('tr', {}, el('th', {}, 'status'), el('th', {}, 'meaning'), el('th', {}, 'content')), responses));
}

function renderWebsocket(asyncapi) {
  const section = document.getElementById('websocket');
  for (const channel of Object.values(asyncapi.channels || {})) {
    section.append(el('p', {}, el('code', {}, channel.address), ' — ', channel.description || ''));
    for (const [key, m] of Object.entries(channel.messages || {})) {
      const payload = m.payload && (m.payload.schema || m.payload);
      section.append(el('div', { class: 'schema', id: `message-${key}` },
        el('h3', {}, m.title || key, ' ', el('span', { class: 'muted' }, m.contentType || '')),
        el('p', {}, m.summary || ''), m.description ? el('p', {}, m.description) : null,
        payload ? el('p', {}, 'Payload: ', typeOf(payload)) : null));
    }
  }
}

function render(openapi, asyncapi) {
  document.getElementById('about').replaceChildren(
    el('span', {}, openapi.info.description || ''), ' ',
    el('span', { class: 'muted' }, `Version ${openapi.info.version}. Documents: `),
    el('a', { href: 'openapi.json' }, 'openapi.json'), ' · ', el('a', { href: 'asyncapi.json' }, 'asyncapi.json'));
  const endpoints = document.getElementById('endpoints');
  for (const [path, item] of Object.entries(openapi.paths)) {
    for (const [method, op] of Object.entries(item)) endpoints.append(renderOperation(path, method, op));
  }
  renderWebsocket(asyncapi);
  const schemas = document.getElementById('schemas');
  const named = Object.entries((openapi.components || {}).schemas || {});
  named.sort(([a], [b]) => a.localeCompare(b));
  for (const [name, s] of named) schemas.append(renderSchema(name, s));
  document.getElementById('toc').replaceChildren(
    el('a', { href: '#endpoints' }, `${endpoints.querySelectorAll('details').length} endpoints`),
    el('a', { href: '#websocket' }, 'WebSocket'),
    el('a', { href: '#schemas' }, `${named.length} types`));
  document.body.dataset.loaded = 'true';
}

async function load() {
  try {
    render(await getJson('openapi.json'), await getJson('asyncapi.json'));
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) {
      document.getElementById('token-form').hidden = false;
      document.getElementById('about').textContent = e.message;
    } else {
      document.getElementById('about').textContent = `The API documents could not be read: ${e.message}`;
    }
  }
}

document.getElementById('token-form').addEventListener('submit', (event) => {
  event.preventDefault();
  setToken(document.getElementById('token').value.trim());
  document.getElementById('token-form').hidden = true;
  load();
});
takeTokenFromFragment();
load();
