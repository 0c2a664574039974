// A new job: the scene in a form, its cost predicted as it changes
// (POST /api/v1/predict, debounced) with where its particles start (POST
// /api/v1/start-preview, in the vessel's 3D view), then submitted (POST /api/v1/jobs).
import { get, post } from '../api.js';
import { h, field, errorBox, showError, fmtBytes, fmtSeconds } from '../dom.js';
import { createViewer, fetchStl, stlObjectFromBuffer, particlesObject } from '../preview.js';

const SIZES = [[160, 96], [320, 180], [640, 360], [1280, 720], [1920, 1080]];
const AXES = { x: [1, 0, 0], y: [0, 1, 0], z: [0, 0, 1] };
const DEBOUNCE_MS = 400;

function num(attrs) { return h('input', { type: 'number', required: true, ...attrs }); }
function select(options, value) {
  return h('select', {}, options.map(([v, text]) => h('option', { value: v, selected: v === value }, text)));
}

// An estimate as the API gives it: a number, or {value, low/high | range: [lo, hi]}.
export function estimateText(est, fmt) {
  if (est === null || est === undefined) return null;
  if (typeof est === 'number') return fmt(est);
  if (typeof est !== 'object' || !Number.isFinite(est.value)) return null;
  const lo = est.low ?? est.min ?? est.lower ?? (Array.isArray(est.range) ? est.range[0] : undefined);
  const hi = est.high ?? est.max ?? est.upper ?? (Array.isArray(est.range) ? est.range[1] : undefined);
  const main = fmt(est.value);
  return Number.isFinite(lo) && Number.isFinite(hi) ? `${main} (likely ${fmt(lo)} to ${fmt(hi)})` : main;
}

// How busy the job workers are, from the public /metrics and /api/v1/health.
async function serverLoad(signal) {
  const [metrics, health] = await Promise.all([
    fetch('/metrics', { signal }).then((r) => (r.ok ? r.text() : '')),
    get('/api/v1/health', { signal })]);
  const gauge = (re) => { const m = metrics.match(re); return m ? Number(m[1]) : null; };
  return {
    running: gauge(/^collidoscope_jobs\{state="running"\} (\d+)/m),
    queued: gauge(/^collidoscope_queue_length (\d+)/m),
    workers: health?.workers ?? null,
  };
}

// What the prediction warns of, in plain words: [{level: 'error'|'note', text}].
function warningsOf(p, load) {
  const out = [];
  // Only a trained cost model says this (the analytic estimate has no training).
  if (p.outside_training) {
    const reasons = Array.isArray(p.outside_reasons) ? p.outside_reasons : [];
    const what = reasons.length ? ` (${reasons.join('; ')})` : '';
    out.push({ level: 'note', text: `This job lies outside what the predictor was trained on${what}. Treat the figures as rough.` });
  }
  // The server's warnings are clauses, as its errors are: shown as sentences, as the note is.
  for (const w of Array.isArray(p.warnings) ? p.warnings : []) {
    const text = String(w.message ?? w);
    if (text) out.push({ level: 'note', text: `${text[0].toUpperCase()}${text.slice(1)}.` });
  }
  if (p.would_wait || Number.isFinite(p.wait_s)) {
    out.push({ level: 'note', text: `This job would wait before it starts${Number.isFinite(p.wait_s) ? ` (about ${fmtSeconds(p.wait_s)})` : ''}.` });
  } else if (load && load.workers && load.running !== null && load.running + (load.queued || 0) >= load.workers) {
    const queued = load.queued ? ` and ${load.queued} waiting` : '';
    out.push({ level: 'note', text: `The server is busy (${load.running} job${load.running === 1 ? '' : 's'} running${queued}, `
      + `${load.workers} at a time): this one would wait its turn.` });
  }
  return out;
}

export async function render(main, ctx, modelParam) {
  const error = errorBox();
  main.append(h('h1', {}, 'New job'), error);
  const [models, algorithms] = await Promise.all([get('/api/v1/models'), get('/api/v1/algorithms')]);
  const usable = models.filter((m) => m.kind !== 'stl' || m.uploaded);
  const wanted = modelParam ? Number(modelParam) : usable[0]?.id;

  const option = (m) => h('option', { value: String(m.id), selected: m.id === wanted },
    `${m.name} (${m.triangles.toLocaleString()} triangles)`);
  const mine = usable.filter((m) => !m.preset);
  const model = h('select', {},
    h('optgroup', { label: 'Presets' }, usable.filter((m) => m.preset).map(option)),
    mine.length ? h('optgroup', { label: 'Your models' }, mine.map(option)) : null);
  const count = num({ min: '1', step: '1', value: '500' });
  // Until the user types one, the radius follows the wall: 1 % of its largest side
  // (set once its mesh is loaded), in whatever units the wall has. That puts the
  // default job on either preset wall inside what the job cost model was trained on
  // (0.5 on wall1 lay outside it, and the first prediction said so).
  const radius = num({ min: '0.000001', step: 'any', value: '1' });
  let radiusTyped = false;
  radius.addEventListener('input', () => { radiusTyped = true; });
  // Optional: a mix of sizes, spread evenly from the radius up to this one (a drum sorts them).
  const radiusMax = num({ min: '0.000001', step: 'any', value: '', required: false });
  // Optional: how fast the pour releases; empty, as fast as its inlet allows.
  const rate = num({ min: '0', step: 'any', value: '', required: false });
  const rateField = field('Pour rate (particles a second)', rate, 'Empty: as fast as the inlet allows.');
  const placement = ['pour', 'fill'].map((k) => h('input', { type: 'radio', name: 'placement', value: k, checked: k === 'pour' }));
  const restitution = num({ min: '0.000001', max: '1', step: 'any', value: '0.4' });
  const friction = num({ min: '0', max: '10', step: 'any', value: '0.3' });
  const contacts = h('input', { type: 'checkbox' });
  const contactModel = select([['linear', 'Spring–dashpot (linear)'], ['hertz_mindlin', 'Hertz–Mindlin']], 'linear');
  const rolling = num({ min: '0', max: '1', step: 'any', value: '0' });
  // How the wall moves: a drum or a mill turns, a sieve shakes. A turn is about
  // the centre of what turns (the scene leaves "center" out).
  const motion = select([['none', 'Stands still'], ['rotate', 'Turns about an axis'],
    ['oscillate', 'Shakes to and fro']], 'none');
  // Which part moves, when the model is a union of shapes (a paddle in a tank).
  const motionPart = h('select');
  const motionPartField = field('What moves', motionPart, 'The others stand still.');
  const showParts = () => {
    const spec = usable.find((m) => String(m.id) === model.value)?.spec || '';
    const parts = spec ? spec.split('+') : [];
    const keep = motionPart.value;
    motionPart.replaceChildren(h('option', { value: '0' }, 'The whole wall'),
      ...(parts.length > 1 ? parts : []).map((p, i) => h('option', { value: String(i + 1), selected: String(i + 1) === keep },
        `Part ${i + 1}: ${p.split(':')[0]}`)));
    motionPartField.hidden = parts.length < 2;
  };
  const motionAxis = select([['x', 'x'], ['y', 'y'], ['z', 'z']], 'y');
  const motionAxisField = field('Axis', motionAxis, ' ');
  const motionAxisHint = motionAxisField.querySelector('.hint');
  const rpm = num({ min: '-1000', max: '1000', step: 'any', value: '6' });
  const amplitude = num({ min: '0', step: 'any', value: '0.5' });
  const frequency = num({ min: '0', max: '100', step: 'any', value: '2' });
  const turnFields = [field('Turns a minute', rpm, 'Negative: the other way.')];
  // A drum of diameter D metres holds its bed below the critical speed 42.3 / sqrt(D) rpm.
  const turnNote = h('p', { class: 'hint' },
    'A drum D metres wide keeps its bed below about 42 / √D turns a minute; faster, the bed sticks to its wall.');
  const shakeFields = [field('Amplitude', amplitude, 'In the wall’s units.'), field('Frequency (Hz)', frequency)];
  const motionRow = h('div', { class: 'row' }, motionAxisField, ...turnFields, ...shakeFields);
  const showPlacement = () => { rateField.hidden = !placement[0].checked; };
  const showMotion = () => {
    for (const f of [...turnFields, turnNote]) f.hidden = motion.value !== 'rotate';
    for (const f of shakeFields) f.hidden = motion.value !== 'oscillate';
    motionRow.hidden = motion.value === 'none';
    if (motion.value === 'none') motionPartField.hidden = true;
    else showParts();
    motionAxisHint.textContent = motion.value === 'rotate' ? 'Through the centre of what turns.' : 'The way it shakes.';
  };
  // Until the user types one, a pour's duration lets its first particles land
  // and settle for two seconds (the prediction says when they reach the wall):
  // 2 s from wall1's top was a fall that never touched it.
  const duration = num({ min: '0.001', step: 'any', value: '2' });
  let durationTyped = false;
  duration.addEventListener('input', () => { durationTyped = true; });
  const fps = num({ min: '0.001', step: 'any', value: '24' });
  // The methods a job may step with ("jobs": not the reference, the engine's
  // test oracle, nor the octree, a detection method only).
  // "auto" times the candidates on the job's particles and keeps the fastest (all are exact).
  const methods = [{ name: 'auto', description: 'Measured on your particles when the job starts: the fastest exact '
    + 'method and grid length for this wall (the result page says what was picked and why).' },
  ...(algorithms.methods || []).filter((m) => m.jobs !== false)];
  const method = select(methods.map((m) => [m.name, m.name]), 'bin');
  const methodHint = h('p', { class: 'hint', id: 'method-hint', 'aria-live': 'polite' });
  method.setAttribute('aria-describedby', 'method-hint');
  const backend = select([['auto', 'automatic'], ['cpu', 'CPU'], ['cuda', 'GPU (CUDA)']], 'auto');
  const vtp = h('input', { type: 'checkbox' });
  const size = select(SIZES.map(([w, ht]) => [`${w}x${ht}`, `${w} × ${ht}`]), '640x360');
  const camera = select([['iso', 'isometric'], ['front', 'front'], ['top', 'top'], ['orbit', 'orbit']], 'iso');
  const color = select([['speed', 'speed'], ['contact', 'contact']], 'speed');
  const wallLook = select([['glass', 'glass'], ['cutaway', 'cut away'], ['hidden', 'hidden']], 'glass');
  const fresh = h('input', { type: 'checkbox' });
  const submitButton = h('button', { type: 'submit' }, 'Submit job');
  const submitStatus = h('p', { class: 'status', role: 'status' });

  const showMethod = () => {
    methodHint.textContent = methods.find((m) => m.name === method.value)?.description || '';
  };
  showMethod();
  showMotion();
  showPlacement();

  // The submission body from the form; throws with a message naming the field.
  function body() {
    const n = (input, label) => {
      const v = input.valueAsNumber;
      if (!Number.isFinite(v) || !input.validity.valid) throw new Error(`${label}: ${input.validationMessage || 'a number is needed'}`);
      return v;
    };
    if (!model.value) throw new Error('Model: make or upload one first (Models page).');
    const [width, height] = size.value.split('x').map(Number);
    const roll = n(rolling, 'Rolling resistance');
    const optional = (input, label) => (input.value === '' ? null : n(input, label));
    const r0 = n(radius, 'Particle radius');
    const r1 = optional(radiusMax, 'Largest radius');
    if (r1 !== null && r1 < r0) throw new Error('Largest radius: at least the radius.');
    const pourRate = placement[0].checked ? optional(rate, 'Pour rate') : null;
    let wallMotion = null;
    if (motion.value === 'rotate') {
      wallMotion = { kind: 'rotate', axis: AXES[motionAxis.value], rpm: n(rpm, 'Turns a minute') };
    } else if (motion.value === 'oscillate') {
      wallMotion = { kind: 'oscillate', axis: AXES[motionAxis.value],
        amplitude: n(amplitude, 'Amplitude'), frequency: n(frequency, 'Frequency') };
    }
    if (wallMotion && !motionPartField.hidden && Number(motionPart.value) > 0) wallMotion.part = Number(motionPart.value);
    const scene = {
      wall: { model: Number(model.value) },
      particles: { count: n(count, 'Particle count'), radius: r1 !== null && r1 > r0 ? [r0, r1] : r0 },
      placement: { kind: placement.find((r) => r.checked).value, ...(pourRate ? { rate: pourRate } : {}) },
      material: { restitution: n(restitution, 'Restitution'), friction: n(friction, 'Friction'),
        ...(roll > 0 ? { rolling_friction: roll } : {}) },
      contact_model: contactModel.value,
      ...(wallMotion ? { wall_motion: wallMotion } : {}),
      particle_contacts: contacts.checked,
      duration: n(duration, 'Duration'),
      fps: n(fps, 'Frames per second'),
      method: method.value,
      ...(method.value === 'auto' ? { grid_length: 'auto' } : {}),
      backend: backend.value,
    };
    if (vtp.checked) scene.output = { vtp: true };
    return { scene, render: { width, height, camera: camera.value, color: color.value, wall: wallLook.value } };
  }

  // ---- the live prediction ----
  const predStatus = h('p', { class: 'status' });
  const predTime = h('dd', { class: 'big' });
  const predMemory = h('dd', { class: 'big' });
  const predFacts = h('dl', { class: 'facts' });
  const predWarnings = h('div');
  const predNote = h('p', { class: 'hint' });
  const headline = h('dl', { class: 'figures' },
    h('div', {}, h('dt', {}, 'Time'), predTime), h('div', {}, h('dt', {}, 'Peak memory'), predMemory));
  const aside = h('aside', { 'aria-labelledby': 'pred-h', class: 'sticky' });
  // On a phone the prediction is below the form: a line at the foot of the screen follows it.
  const predMini = h('button', { type: 'button', class: 'pred-mini', 'aria-hidden': 'true', tabindex: '-1',
    onclick: () => aside.scrollIntoView({ behavior: 'smooth' }) });
  const mini = (text) => { predMini.textContent = text; };
  let timer = null;
  let inflight = null;
  let left = false;  // the visitor left the page: a wall file that arrives later starts nothing
  function schedule() {
    if (left) return;
    clearTimeout(timer);
    predStatus.textContent = 'Updating…';
    timer = setTimeout(predict, DEBOUNCE_MS);
  }
  function showWarnings(list) {
    predWarnings.replaceChildren(...list.map((w) => h('p', { class: `alert ${w.level}` }, w.text)));
  }
  function clearFigures() {
    predTime.textContent = '—';
    predMemory.textContent = '—';
    predFacts.replaceChildren();
    predNote.textContent = '';
  }
  // ---- where the particles start ----
  const startBox = h('div', { class: 'preview-box', id: 'start-preview' });
  const startCaption = h('p', { class: 'status', 'aria-live': 'polite' }, 'Shown once the form is complete.');
  const startViewer = createViewer(startBox, 'The vessel, and where the particles start');
  let wallShown = null;  // the model whose wall the view shows
  // Each wall's file, fetched and parsed once for its size (the radius) and its
  // first showing; a later showing parses the bytes again, since the view
  // disposes the mesh it drops.
  const walls = new Map();  // model id -> Promise<{ buffer, largestSide, unshown }>
  function wallFile(m) {
    if (!walls.has(m.id)) {
      walls.set(m.id, fetchStl(m.stl).then((buffer) => {
        const mesh = stlObjectFromBuffer(buffer);
        return { buffer, largestSide: mesh.largestSide, unshown: mesh };
      }).catch((e) => { walls.delete(m.id); throw e; }));
    }
    return walls.get(m.id);
  }
  async function wallMesh(m) {
    const w = await wallFile(m);
    const mesh = w.unshown ?? stlObjectFromBuffer(w.buffer);
    w.unshown = null;
    return mesh;
  }
  async function showStart(b, signal) {
    const m = usable.find((x) => String(x.id) === model.value);
    if (!m) return;
    try {
      if (wallShown !== m.id) {
        const { object } = await wallMesh(m);
        if (signal.aborted) return;
        startViewer.show(object, { seeThrough: true });
        wallShown = m.id;
      }
      const start = await post('/api/v1/start-preview', b, { signal });
      startViewer.setExtra(start.shown.length ? particlesObject(start.shown) : null);
      if (start.note) {
        startCaption.textContent = `${start.particles.toLocaleString()} particles: ${start.note}.`;
        return;
      }
      const n = start.particles.toLocaleString();
      const some = start.shown.length < start.particles ? ` (${start.shown.length.toLocaleString()} of them shown)` : '';
      const last = Math.max(0, ...start.release_s);
      // Released after the run ends: never in it (the share of those shown, of all).
      const end = Number(b.scene.duration);
      const late = Math.round(start.release_s.filter((t) => t > end).length * start.particles / start.shown.length);
      const text = last > 0
        ? `${n} particles are poured in from the places shown, the last after ${fmtSeconds(last)}${some}.`
          + (late > 0 ? ` The run ends at ${fmtSeconds(end)}: about ${late.toLocaleString()} of them never enter it.` : '')
        : `${n} particles start where shown${some}.`;
      startCaption.textContent = text;
      startViewer.setLabel(`3D view of ${m.name}: ${text}`);
    } catch (e) {
      if (e.name === 'AbortError' || signal.aborted) return;
      startViewer.setExtra(null);
      startCaption.textContent = e.status === 400 ? `The particles cannot start: ${e.message}.`
        : `Where the particles start is not shown: ${e.message}`;
    }
  }

  // The radius the wall's size suggests, once its mesh is loaded (see `radius`).
  let fittedFor = null;  // the model whose size set it
  async function fitRadius() {
    const m = usable.find((x) => String(x.id) === model.value);
    if (!m || radiusTyped || fittedFor === m.id) return;
    fittedFor = m.id;
    try {
      const { largestSide } = await wallFile(m);
      const fitting = String(Number((largestSide / 100).toPrecision(2)));
      if (radiusTyped || String(m.id) !== model.value || !(largestSide > 0) || fitting === radius.value) return;
      radius.value = fitting;
      schedule();
    } catch { /* the 3D view says why the wall did not load */ }
  }

  async function predict() {
    inflight?.abort();
    const me = new AbortController();
    inflight = me;
    let b;
    try { b = body(); } catch (e) {
      predStatus.textContent = 'Not predicted: the form needs a change.';
      clearFigures();
      showWarnings([{ level: 'error', text: e.message }]);
      mini('No prediction: the form needs a change. Show why ↑');
      return;
    }
    const load = serverLoad(me.signal).catch(() => null);
    try {
      const p = await post('/api/v1/predict', b, { signal: me.signal });
      const l = await load;
      if (inflight !== me) return;
      const lands = Number(p.first_contact_s);
      const fitting = String(placement[0].checked && lands > 0 ? Math.max(2, Math.ceil(lands + 2)) : 2);
      if (!durationTyped && fitting !== duration.value) {
        duration.value = fitting;
        schedule();
        return;
      }
      const i = p.inputs || {};
      const fact = (k, v) => [h('dt', {}, k), h('dd', {}, v ?? '—')];
      const time = estimateText(p.total_time_s, fmtSeconds);
      predTime.textContent = time ?? 'not predicted yet';
      predTime.classList.toggle('words', !time);
      predMemory.textContent = estimateText(p.peak_host_bytes, fmtBytes) ?? '—';
      const memoryText = predMemory.textContent;
      predFacts.replaceChildren(
        // With the initial frame, as the result page counts them.
        ...fact('Frames', i.frames == null ? null : (i.frames + 1).toLocaleString()),
        ...fact('Particles', i.particles?.toLocaleString()),
        ...fact('Files written', estimateText(p.output_bytes, fmtBytes)),
        ...fact('Wall triangles', i.triangles?.toLocaleString()),
        ...fact('Pieces after division', i.pieces?.toLocaleString()),
        ...fact('Method', i.method),
        ...fact('Estimated by', p.basis === 'analytic' ? 'formula (no trained model on this server)' : p.basis),
        ...(p.pace ? fact('Machine pace', `${p.pace.factor.toFixed(2)}× the model's time (its last ${p.pace.jobs} jobs)`) : []));
      predNote.textContent = p.note ? `${p.note[0].toUpperCase()}${p.note.slice(1)}.` : '';
      showWarnings(warningsOf(p, l));
      mini(`Prediction: ${time ?? 'time not predicted yet'}, ${memoryText} of memory`
        + `${predWarnings.childElementCount ? ' — see the warnings' : ''}. Show ↑`);
      predStatus.textContent = 'Up to date.';
      showStart(b, me.signal);
    } catch (e) {
      if (e.name === 'AbortError' || inflight !== me) return;
      clearFigures();
      // 409 or 507: the server would refuse the job as it stands (too much
      // memory, or files that would not fit on its disk).
      const refused = e.status === 409 || e.status === 507;
      const text = refused ? `This job would be refused: ${e.message}.`
        : e.status === 400 ? `Check the form: ${e.message}.` : `No prediction: ${e.message}`;
      showWarnings([{ level: 'error', text }]);
      predStatus.textContent = refused ? 'Would be refused.' : 'Not predicted.';
      mini(`${refused ? 'This job would be refused' : 'No prediction'}. Show why ↑`);
      // A refused job's particles still start somewhere: the view follows the form.
      if (refused) showStart(b, me.signal);
      // 503: the server's threads for such requests are busy; ask again when it says.
      if (e.status === 503) {
        setTimeout(() => { if (inflight === me) predict(); }, 1000 * (e.retryAfter || 1));
      }
    }
  }

  const form = h('form', { class: 'card', novalidate: true, 'aria-labelledby': 'scene-h' },
    field('Wall (a model)', model, 'Build or upload one on the Models page.'),
    h('fieldset', {}, h('legend', {}, 'Particles'),
      h('div', { class: 'row' }, field('Count', count), field('Radius', radius, 'In the wall’s units; 1 % of its size until you type one.'),
        field('Largest radius', radiusMax, 'Optional: sizes spread evenly up to it.'))),
    h('fieldset', {}, h('legend', {}, 'Placement'),
      h('label', { class: 'check' }, placement[0], 'Pour: particles fall in from above the vessel'),
      h('label', { class: 'check' }, placement[1], 'Fill: particles start spread through the vessel'),
      rateField),
    h('fieldset', {}, h('legend', {}, 'Material'),
      h('div', { class: 'row' }, field('Restitution', restitution, 'Bounce, 0 to 1.'), field('Friction', friction, '0 to 10.')),
      h('div', { class: 'row' }, field('Contact law', contactModel, 'Hertz–Mindlin stiffens as particles press in.'),
        field('Rolling resistance', rolling, '0 to 1; 0: a ball rolls on forever.')),
      h('label', { class: 'check' }, contacts, 'Particles also collide with each other')),
    h('fieldset', {}, h('legend', {}, 'Wall motion'),
      h('div', { class: 'row' }, field('The wall', motion), motionPartField), motionRow, turnNote),
    h('fieldset', {}, h('legend', {}, 'Time'),
      h('div', { class: 'row' }, field('Duration (simulated seconds)', duration), field('Frames per second', fps))),
    h('fieldset', {}, h('legend', {}, 'Computation'),
      h('div', { class: 'row' }, field('Detection method', method), field('Backend', backend, 'Automatic: the GPU when the server has one.')),
      methodHint),
    h('fieldset', {}, h('legend', {}, 'Video and files'),
      h('div', { class: 'row' }, field('Size', size), field('Camera', camera), field('Colour by', color), field('Wall', wallLook)),
      h('label', { class: 'check' }, vtp, 'Also write ParaView files (one .vtp per frame)')),
    h('label', { class: 'check' }, fresh, 'Run again even if an identical result exists'),
    h('div', { class: 'actions' }, submitButton), submitStatus);

  form.addEventListener('input', schedule);
  form.addEventListener('change', (e) => {
    if (e.target === method) showMethod();
    if (e.target === motion || e.target === model) showMotion();
    if (e.target === model) fitRadius();
    if (placement.includes(e.target)) showPlacement();
    schedule();
  });
  form.addEventListener('submit', async (e) => {
    e.preventDefault();
    showError(error, null);
    let b;
    try { b = body(); } catch (err) { showError(error, err); error.scrollIntoView({ block: 'nearest' }); return; }
    if (fresh.checked) b.fresh = true;
    submitButton.disabled = true;
    submitStatus.textContent = 'Submitting…';
    try {
      const job = await post('/api/v1/jobs', b);
      ctx.go(`#/jobs/${job.id}`);
    } catch (err) {
      showError(error, new Error(`The job was not accepted: ${err.message}`));
      error.scrollIntoView({ block: 'nearest' });
      submitStatus.textContent = '';
      submitButton.disabled = false;
    }
  });

  main.append(h('div', { class: 'split wide-left' },
    h('section', {}, h('h2', { id: 'scene-h' }, 'Scene'), form,
      h('h2', { id: 'start-h' }, 'Where the particles start'),
      h('div', { class: 'card', 'aria-labelledby': 'start-h' }, startBox, startCaption)),
    aside), predMini);
  aside.append(h('h2', { id: 'pred-h' }, 'Prediction'),
    h('div', { class: 'card', id: 'prediction' },
      h('div', { 'aria-live': 'polite' }, predStatus, headline, predWarnings),
      predNote, predFacts),
    h('p', { class: 'hint' }, 'What this job will cost, estimated by the server before it runs. It follows the form as you change it.'));
  clearFigures();
  predict();
  fitRadius();
  return () => { left = true; clearTimeout(timer); inflight?.abort(); startViewer.dispose(); };
}
