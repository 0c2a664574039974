// Models: the presets and your own, a 3D preview, a builder for parametric
// vessels (unions of parts) and an STL upload.
import { get, post, put, del } from '../api.js';
import { h, tableBox, field, errorBox, showError, fmtBytes } from '../dom.js';
import { createViewer, stlObject, stlObjectFromBuffer, draftObject } from '../preview.js';

// The parameters of each shape (sim/shapes.cpp), with the builder's starting values.
const SHAPES = {
  cylinder: [['r', 'Radius r', 5], ['h', 'Height h', 10], ['segments', 'Segments', 48]],
  cone: [['r1', 'Bottom radius r1', 5], ['r2', 'Top radius r2', 0], ['h', 'Height h', 10], ['segments', 'Segments', 48]],
  funnel: [['r1', 'Bottom radius r1', 2], ['r2', 'Top radius r2', 8], ['h', 'Height h', 8], ['segments', 'Segments', 48]],
  box: [['x', 'Width x', 10], ['y', 'Depth y', 10], ['z', 'Height z', 10]],
  sphere: [['r', 'Radius r', 5], ['subdivisions', 'Subdivisions', 3]],
};
const SHAPE_NAMES = { cylinder: 'Cylinder', cone: 'Cone', funnel: 'Funnel', box: 'Box', sphere: 'Sphere' };
// Which ends of a lathe are closed (the engine's "caps"), and each shape's default.
const CAPS = [['bottom', 'Open top (a cup)'], ['both', 'Closed at both ends'], ['none', 'Open at both ends'],
  ['top', 'Open bottom']];
// The engine's default (left out of the spec) and the builder's first choice.
const ENGINE_CAPS = { cylinder: 'both', cone: 'both', funnel: 'none' };
const FIRST_CAPS = { cylinder: 'bottom', cone: 'bottom', funnel: 'none' };
// The line a lathe (cylinder, cone, funnel) is turned about; along x or y it lies on its side.
const AXES = [['z', 'z (standing)'], ['x', 'x (lying)'], ['y', 'y (lying)']];
const OFFSETS = [['dx', 'Offset x', 0], ['dy', 'Offset y', 0], ['dz', 'Offset z', 0]];
const INTEGER_KEYS = new Set(['segments', 'subdivisions']);

// Starting points for the builder.
const EXAMPLES = {
  cup: [['cylinder', { caps: 'bottom' }]],
  funnel: [['funnel', { r1: 2, r2: 8, h: 8, dz: 12, caps: 'none' }], ['cylinder', { r: 5, h: 10, caps: 'bottom' }]],
  bowl: [['cone', { r1: 2, r2: 8, h: 6, caps: 'bottom' }]],
  box: [['box', {}]],
  ball: [['sphere', {}]],
  drum: [['cylinder', { r: 5, h: 4, caps: 'both', axis: 'y' }]],
  tank: [['cylinder', { r: 5, h: 6, caps: 'bottom' }], ['box', { x: 7.5, y: 0.6, z: 2, dz: 0.3 }]],
};
const EXAMPLE_NAMES = { cup: 'A cup', funnel: 'A funnel over a cup', bowl: 'A bowl (open cone)', box: 'A closed box',
  ball: 'A ball', drum: 'A drum on its side (to turn)', tank: 'A tank with a paddle (to stir)' };

// The engine's wall spec for parts: "cylinder:r=5,h=10,caps=bottom+funnel:...".
// (The API's "parts" takes numbers only, so caps go through the spec.)
export function specOf(parts) {
  return parts.map((p) => {
    const params = Object.entries(p).filter(([k]) => k !== 'shape').map(([k, v]) => `${k}=${v}`);
    return params.length ? `${p.shape}:${params.join(',')}` : p.shape;
  }).join('+');
}

export async function render(main) {
  const viewers = [];
  const listError = errorBox();
  const tbody = h('tbody');
  const previewBox = h('div', { class: 'preview-box' });
  const previewCaption = h('p', { class: 'status', 'aria-live': 'polite' }, 'Choose “Preview” on a model.');
  const viewer = createViewer(previewBox, 'No model shown yet');
  viewers.push(viewer);
  previewBox.id = 'model-preview';

  async function preview(m) {
    previewCaption.textContent = `Loading ${m.name}…`;
    try {
      const { object, triangles } = await stlObject(m.stl);
      viewer.show(object);
      const text = `${m.name}: ${triangles.toLocaleString()} triangles`;
      viewer.setLabel(`3D view of the model ${text}`);
      previewCaption.textContent = text;
    } catch (e) {
      previewCaption.textContent = '';
      showError(listError, new Error(`The preview of ${m.name} failed: ${e.message || e}`));
    }
  }

  let shownOnce = false;
  async function refresh(focusId) {
    showError(listError, null);
    let models;
    try { models = await get('/api/v1/models'); } catch (e) { showError(listError, e); return; }
    tbody.replaceChildren(...models.map((m) => {
      const ready = m.kind !== 'stl' || m.uploaded;
      const actions = h('td', {},
        h('div', { class: 'actions' },
          h('button', { type: 'button', class: 'secondary small', disabled: !ready, onclick: () => preview(m),
            'aria-label': `Preview ${m.name}` }, 'Preview'),
          ready ? h('a', { class: 'button secondary small', href: `#/new?model=${m.id}`, 'aria-label': `Use in a job: ${m.name}` },
            'Use in a job') : null,
          m.preset ? null : h('button', { type: 'button', class: 'danger small', 'aria-label': `Delete ${m.name}`,
            onclick: async () => {
              if (!confirm(`Delete the model “${m.name}”? Jobs that used it keep their copy.`)) return;
              try { await del(`/api/v1/models/${m.id}`); refresh(); } catch (e) { showError(listError, e); }
            } }, 'Delete')));
      const detail = m.preset ? 'from the paper' : m.spec ? h('code', {}, m.spec) : (m.stl_bytes ? fmtBytes(m.stl_bytes) : '');
      return h('tr', {},
        h('th', { scope: 'row' }, m.name, detail ? h('div', { class: 'hint spec' }, detail) : null),
        h('td', {}, m.preset ? 'preset' : m.kind === 'stl' ? 'STL' : 'built', m.kind === 'stl' && !m.uploaded ? ' (no file yet)' : ''),
        h('td', { class: 'num' }, m.triangles ? m.triangles.toLocaleString() : '—'),
        actions);
    }));
    // A new model is shown at once; on arrival, the first one.
    const m = models.find((x) => x.id === focusId) || (shownOnce ? null : models[0]);
    shownOnce = true;
    if (m) {
      await preview(m);
      if (focusId) previewBox.scrollIntoView({ block: 'nearest', behavior: 'smooth' });
    }
  }

  main.append(
    h('h1', {}, 'Models'),
    h('p', { class: 'lead' }, 'A model is the wall the particles collide with: a preset from the paper, a vessel you build from shapes, or a mesh you upload as STL.'),
    h('section', { 'aria-labelledby': 'list-h', class: 'split wide-left' },
      h('div', {},
        h('h2', { id: 'list-h' }, 'Presets and your models'), listError,
        tableBox('Models', h('table', {},
          h('thead', {}, h('tr', {}, h('th', { scope: 'col' }, 'Name'), h('th', { scope: 'col' }, 'Kind'),
            h('th', { scope: 'col', class: 'num' }, 'Triangles'),
            h('th', { scope: 'col' }, h('span', { class: 'visually-hidden' }, 'Actions')))),
          tbody))),
      h('div', {}, h('h2', { id: 'preview-h' }, 'Preview'), previewBox, previewCaption)),
    builder(viewers, (id) => refresh(id)),
    uploader(viewers, (id) => refresh(id)));
  await refresh();
  return () => viewers.forEach((v) => v.dispose());
}

// The parametric builder: a name and a list of parts, a live draft preview.
function builder(viewers, created) {
  const name = h('input', { required: true, maxlength: '128', value: 'my cup', autocomplete: 'off' });
  // The name follows the example until the user types one.
  let nameTyped = false;
  name.addEventListener('input', () => { nameTyped = true; });
  const example = h('select', {}, Object.entries(EXAMPLE_NAMES).map(([k, t]) => h('option', { value: k }, t)));
  const partsBox = h('div');
  const error = errorBox();
  const status = h('p', { class: 'status', role: 'status' });
  const specLine = h('p', { class: 'hint spec-line' });
  const draftBox = h('div', { class: 'preview-box' });
  const draft = createViewer(draftBox, 'Draft of the vessel being built');
  viewers.push(draft);
  const parts = [];

  function readParts() {
    return parts.map((p, i) => {
      const out = { shape: p.shape.value };
      for (const [key, input] of Object.entries(p.inputs)) {
        if (input.value === '' && key.startsWith('d')) continue;  // an empty offset is 0
        const v = input.valueAsNumber;
        if (!Number.isFinite(v)) throw new Error(`Part ${i + 1}: ${input.dataset.label} must be a number.`);
        if (INTEGER_KEYS.has(key) && !Number.isInteger(v)) throw new Error(`Part ${i + 1}: ${input.dataset.label} must be a whole number.`);
        if (key.startsWith('d') && v === 0) continue;  // keeps the spec short
        out[key] = v;
      }
      if (p.caps && p.caps.value !== ENGINE_CAPS[out.shape]) out.caps = p.caps.value;
      if (p.axis && p.axis.value !== 'z') out.axis = p.axis.value;
      return out;
    });
  }

  function redraw() {
    try {
      const read = readParts();
      draft.show(draftObject(read));
      specLine.replaceChildren('Wall spec: ', h('code', {}, specOf(read)));
      showError(error, null);
    } catch (e) { showError(error, e); }
  }

  function addPart(shape = 'cylinder', values = {}) {
    const select = h('select', {}, Object.keys(SHAPES).map((s) => h('option', { value: s, selected: s === shape }, SHAPE_NAMES[s])));
    const paramsBox = h('div', { class: 'row' });
    const p = { shape: select, inputs: {}, caps: null, axis: null };
    const fieldsetEl = h('fieldset', { class: 'part' });
    const legend = h('legend');
    function build() {
      p.inputs = {};
      const spec = [...SHAPES[select.value], ...OFFSETS];
      const fields = spec.map(([key, label, dflt]) => {
        const input = h('input', { type: 'number', step: INTEGER_KEYS.has(key) ? '1' : 'any',
          value: String(values[key] ?? dflt), oninput: redraw });
        input.dataset.label = label;
        p.inputs[key] = input;
        return field(label, input);
      });
      p.caps = null;
      p.axis = null;
      if (FIRST_CAPS[select.value]) {
        const want = values.caps || FIRST_CAPS[select.value];
        p.caps = h('select', { onchange: redraw }, CAPS.map(([v, t]) => h('option', { value: v, selected: v === want }, t)));
        const axis = values.axis || 'z';
        p.axis = h('select', { onchange: redraw }, AXES.map(([v, t]) => h('option', { value: v, selected: v === axis }, t)));
        fields.splice(SHAPES[select.value].length, 0, field('Ends', p.caps), field('Axis', p.axis));
      }
      paramsBox.replaceChildren(...fields);
    }
    select.addEventListener('change', () => { values = {}; build(); redraw(); });
    const remove = h('button', { type: 'button', class: 'secondary small', onclick: () => {
      if (parts.length === 1) return;
      parts.splice(parts.indexOf(p), 1);
      fieldsetEl.remove();
      renumber();
      redraw();
    } });
    p.remove = remove;
    p.legend = legend;
    fieldsetEl.append(legend, field('Shape', select), paramsBox, h('div', { class: 'actions' }, remove));
    build();
    parts.push(p);
    partsBox.append(fieldsetEl);
    renumber();
  }
  function renumber() {
    parts.forEach((p, i) => {
      p.legend.textContent = `Part ${i + 1}`;
      p.remove.hidden = parts.length === 1;
      p.remove.textContent = `Remove part ${i + 1}`;
    });
  }
  function useExample() {
    if (!nameTyped) name.value = `my ${example.value}`;
    parts.splice(0).forEach(() => {});
    partsBox.replaceChildren();
    for (const [shape, values] of EXAMPLES[example.value]) addPart(shape, values);
    redraw();
  }
  example.addEventListener('change', useExample);

  const form = h('form', { class: 'card', novalidate: true },
    h('div', { class: 'row' }, field('Name', name), field('Start from', example)),
    h('p', { class: 'hint' }, 'Shapes stand on z = 0 around the z axis (a lathe along x or y lies on its side, from 0 to its height); '
      + 'the offsets move a part. Several parts make one wall (their union).'),
    partsBox,
    h('div', { class: 'actions' },
      h('button', { type: 'button', class: 'secondary', onclick: () => { addPart('funnel', { dz: 12 }); redraw(); } }, 'Add a part')),
    error, status,
    h('div', { class: 'actions' }, h('button', { type: 'submit' }, 'Create model')));
  form.addEventListener('submit', async (e) => {
    e.preventDefault();
    showError(error, null);
    try {
      if (!name.value.trim()) throw new Error('Name: required.');
      const spec = specOf(readParts());
      status.textContent = 'Creating…';
      const m = await post('/api/v1/models', { name: name.value.trim(), spec });
      status.textContent = `Created “${m.name}”: ${m.triangles.toLocaleString()} triangles.`;
      created(m.id);
    } catch (err) { status.textContent = ''; showError(error, err); }
  });
  useExample();
  return h('section', { 'aria-labelledby': 'build-h' }, h('h2', { id: 'build-h' }, 'Build a vessel'),
    h('div', { class: 'split' }, form,
      h('div', { class: 'sticky' }, h('h3', {}, 'Draft preview'), draftBox, specLine)));
}

// Upload an STL: the model is made first, then its file is sent as the body.
function uploader(viewers, created) {
  const name = h('input', { required: true, maxlength: '128', autocomplete: 'off' });
  const file = h('input', { type: 'file', accept: '.stl,model/stl,application/sla', required: true });
  const error = errorBox();
  const status = h('p', { class: 'status', role: 'status' });
  const localBox = h('div', { class: 'preview-box' });
  const local = createViewer(localBox, 'Preview of the chosen file');
  viewers.push(local);
  const localCaption = h('p', { class: 'status', 'aria-live': 'polite' }, 'Choose a file to see it here before it is sent.');

  file.addEventListener('change', async () => {
    showError(error, null);
    status.textContent = '';
    const f = file.files[0];
    if (!f) return;
    if (!name.value) name.value = f.name.replace(/\.stl$/i, '');
    try {
      const { object, triangles } = stlObjectFromBuffer(await f.arrayBuffer());
      local.show(object);
      local.setLabel(`3D view of the file ${f.name}`);
      localCaption.textContent = `${f.name}: ${fmtBytes(f.size)}, ${triangles.toLocaleString()} triangles.`;
    } catch (e) {
      localCaption.textContent = `${f.name} does not read as STL in the browser (${e.message || e}); the server will say why when you upload it.`;
    }
  });

  const form = h('form', { class: 'card', novalidate: true },
    field('STL file', file, 'Binary or ASCII STL. The server checks it and drops triangles without area.'),
    field('Name', name),
    error, status,
    h('div', { class: 'actions' }, h('button', { type: 'submit' }, 'Upload')));
  form.addEventListener('submit', async (e) => {
    e.preventDefault();
    showError(error, null);
    const f = file.files[0];
    if (!f) { showError(error, new Error('Choose an STL file first.')); return; }
    if (!name.value.trim()) { showError(error, new Error('Name: required.')); return; }
    let m = null;
    try {
      status.textContent = `Uploading ${fmtBytes(f.size)}…`;
      m = await post('/api/v1/models', { name: name.value.trim(), kind: 'stl' });
      const stored = await put(`/api/v1/models/${m.id}/stl`, f, { contentType: 'model/stl' });
      status.textContent = `Uploaded “${stored.name}”: ${stored.triangles.toLocaleString()} triangles`
        + (stored.dropped_zero_area ? `, ${stored.dropped_zero_area} without area dropped.` : '.');
      created(m.id);
    } catch (err) {
      status.textContent = '';
      showError(error, new Error(`The server did not take ${f.name}: ${err.message || err}`));
      // A model whose file was refused would linger as "no file yet": remove it.
      if (m) del(`/api/v1/models/${m.id}`).catch(() => {});
    }
  });
  return h('section', { 'aria-labelledby': 'upload-h' }, h('h2', { id: 'upload-h' }, 'Upload an STL'),
    h('div', { class: 'split' }, form, h('div', {}, h('h3', {}, 'File preview'), localBox, localCaption)));
}
