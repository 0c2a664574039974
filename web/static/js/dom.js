// Small DOM helpers. Text always goes in as text nodes (never innerHTML), so
// names and error messages from the server cannot inject markup.

// h('button', {type: 'button', onclick: f}, 'Save'): an element.
export function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith('on') && typeof v === 'function') el.addEventListener(k.slice(2), v);
    else if (k === 'class') el.className = v;
    // Properties where the attribute is not the state (a textarea's value, checked, hidden...).
    else if (k === 'value' || (k in el && typeof v !== 'string')) el[k] = v;
    else el.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children.flat(Infinity)) {
    if (c === undefined || c === null || c === false) continue;
    el.append(c instanceof Node ? c : String(c));
  }
  return el;
}

// A labelled form control: <div><label for=id>text</label>control<p hint></div>.
let nextId = 0;
export function field(labelText, control, hint) {
  if (!control.id) control.id = 'f' + (++nextId);
  const parts = [h('label', { for: control.id }, labelText), control];
  if (hint) {
    const hintEl = h('p', { class: 'hint', id: control.id + '-hint' }, hint);
    control.setAttribute('aria-describedby', hintEl.id);
    parts.push(hintEl);
  }
  return h('div', {}, parts);
}

// An error box that screen readers announce when its text changes.
export function errorBox() {
  return h('div', { class: 'alert error', role: 'alert' });
}
export function showError(box, err) {
  const text = err ? (err.message || String(err)) : '';
  box.textContent = text && text[0].toUpperCase() + text.slice(1);  // the API's messages start in lower case
}

export function fmtBytes(n) {
  if (n === null || n === undefined || !Number.isFinite(n)) return '—';
  const units = ['B', 'KiB', 'MiB', 'GiB', 'TiB'];
  let i = 0;
  // The unit is chosen for the value as it will be shown: 1,048,575 B is 1.0 MiB, not 1024.0 KiB.
  while (i < units.length - 1 && (i === 0 ? n : Math.round(n * 10) / 10) >= 1024) { n /= 1024; i++; }
  return `${n.toFixed(i === 0 ? 0 : 1)} ${units[i]}`;
}

export function fmtSeconds(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return '—';
  // Each range by the value as shown: 0.9996 s is 1.0 s, not 1000 ms; 179.6 s is 3 min 0 s, not 2 min 60 s.
  if (Math.round(s * 1000) < 1000) return `${(s * 1000).toFixed(0)} ms`;
  if (Math.round(s * 10) < 1200) return `${s.toFixed(1)} s`;
  const t = Math.round(s);
  return `${Math.floor(t / 60)} min ${t % 60} s`;
}

export function fmtDate(unixSeconds) {
  if (!unixSeconds) return '—';
  return new Date(unixSeconds * 1000).toLocaleString();
}

// The wall a scene names, in words: "wall1", "model 3", a shape spec.
export function wallLabel(wall, modelsById) {
  if (wall && typeof wall === 'object' && 'model' in wall) {
    const m = modelsById && modelsById.get(wall.model);
    return m ? m.name : `model ${wall.model}`;
  }
  return typeof wall === 'string' ? wall : JSON.stringify(wall);
}

// A table in a box that scrolls sideways on narrow screens; focusable so
// keyboard users can scroll it too.
export function tableBox(label, table) {
  return h('div', { class: 'table-wrap', tabindex: '0', role: 'region', 'aria-label': label }, table);
}
