// Administrators: the run log (GET /api/v1/admin/logs), one row per finished
// job with its inputs and measured against predicted cost, paged by id; the
// algorithms (GET /api/v1/algorithms); the job cost models' training
// (GET /api/v1/admin/predictor): loss curves, held-out predictions against
// measurements, intervals, and retraining them on the jobs the service ran
// (POST /api/v1/admin/predictor/retrain).
import { get, post } from '../api.js';
import { h, tableBox, errorBox, showError, fmtBytes, fmtSeconds, fmtDate } from '../dom.js';
import { algorithmsTable } from './methods.js';
import { predictorCharts } from '../chart.js';

const PAGE = 50;

export async function render(main) {
  const error = errorBox();
  const tbody = h('tbody');
  const status = h('p', { class: 'status', role: 'status' });
  const older = h('button', { type: 'button', class: 'secondary', hidden: true }, 'Older rows');
  const summary = h('div');
  const rows = [];
  let before = 0;

  async function load() {
    older.disabled = true;
    try {
      const page = await get(`/api/v1/admin/logs?limit=${PAGE}${before ? `&before=${before}` : ''}`);
      rows.push(...page);
      tbody.append(...page.map(rowOf));
      if (page.length) before = page[page.length - 1].id;
      older.hidden = page.length < PAGE;
      status.textContent = rows.length ? `${rows.length} row${rows.length === 1 ? '' : 's'} shown, newest first.`
        : 'No finished jobs yet: the log fills as jobs finish.';
      summary.replaceChildren(memorySummary(rows));
    } catch (e) { showError(error, e); }
    older.disabled = false;
  }
  older.addEventListener('click', load);

  const cols = [['Row'], ['Finished'], ['Job'], ['Particles', 1], ['Triangles', 1], ['Method'], ['Ran on'],
    ['Time', 1], ['Predicted time', 1], ['Peak memory', 1], ['Predicted memory', 1]];
  const predictor = h('div');
  const retrainStatus = h('p', { role: 'status', id: 'retrain-status' });
  const retrainButton = h('button', { type: 'button', class: 'secondary' }, 'Retrain now');
  let left = false;  // the visitor left the page: its polling stops
  let disposeCharts = [];  // the charts on show (their observers), freed when replaced
  const freeCharts = () => { for (const d of disposeCharts) { try { d?.(); } catch { /* gone */ } } disposeCharts = []; };
  async function showPredictor() {
    let answer = null;
    try { answer = await get('/api/v1/admin/predictor'); } catch (e) { showError(error, e); }
    if (!answer || left) return null;
    freeCharts();
    predictor.replaceChildren(...predictorSections(answer.models, disposeCharts));
    if (answer.retrain) retrainStatus.replaceChildren(...retrainText(answer.retrain));
    return answer;
  }
  retrainButton.addEventListener('click', async () => {
    retrainButton.disabled = true;
    try {
      await post('/api/v1/admin/predictor/retrain', {});
      retrainStatus.textContent = 'Retraining…';
      // Training takes seconds to a minute; poll until it has ended.
      for (let i = 0; i < 300 && !left; i++) {
        await new Promise((r) => setTimeout(r, 1000));
        if (left) break;
        const answer = await showPredictor();
        if (!answer?.retrain?.running) break;
      }
    } catch (e) { showError(error, e); }
    retrainButton.disabled = false;
  });
  await showPredictor();
  let algorithms = null;
  try { algorithms = await get('/api/v1/algorithms'); } catch (e) { showError(error, e); }
  main.append(
    h('h1', {}, 'Administration'),
    error,
    h('section', { 'aria-labelledby': 'log-h' },
      h('h2', { id: 'log-h' }, 'Run log'),
      h('p', {}, 'Every finished job: what it was given, what it cost, and what was predicted before it ran. These rows are what the cost model will train on.'),
      status,
      tableBox('Run log table', h('table', { class: 'compact' },
        h('caption', { class: 'visually-hidden' }, 'Run log, newest first'),
        h('thead', {}, h('tr', {}, cols.map(([c, n]) => h('th', { scope: 'col', class: n ? 'num' : undefined }, c)))),
        tbody)),
      h('div', { class: 'actions' }, older)),
    h('section', { 'aria-labelledby': 'pred-h' },
      h('h2', { id: 'pred-h' }, 'Cost predictor'),
      predictor,
      summary,
      h('h3', {}, 'Retraining'),
      h('p', { class: 'hint' }, 'A candidate learns from the job logs the server was given (the committed sweeps by default) and the jobs this service ran, '
        + 'and replaces the model in use only when it misses held-out jobs (a fixed share, never trained on) by less.'),
      retrainStatus,
      h('div', { class: 'actions' }, retrainButton)),
    h('section', { 'aria-labelledby': 'alg-h' },
      h('h2', { id: 'alg-h' }, 'Algorithms'),
      algorithms ? algorithmsTable(algorithms) : h('p', {}, 'The list could not be read.')));
  await load();
  return () => { left = true; freeCharts(); };
}

// One section per job cost model in use: what it was trained on, its intervals,
// charts (whose dispose functions go into `disposers`).
function predictorSections(models, disposers) {
  if (!models.length) {
    return [h('div', { class: 'alert note' }, h('strong', {}, 'No job cost model is loaded. '),
      'Jobs are priced by the engine’s formula for memory, and their time is not predicted. ',
      'Train one with ', h('code', {}, 'collidoscope calibrate --jobs'), ' and ', h('code', {}, 'collidoscope gvm train'),
      ', then start the server with ', h('code', {}, '--cost-model'), '.')];
  }
  const factor = (f) => (f >= 1 ? `×${f.toFixed(2)}` : `÷${(1 / f).toFixed(2)}`);
  return models.map((m) => {
    const box = h('div', { class: 'chart-row' });
    const costs = Object.entries(m.costs || {}).filter(([, c]) => c.interval_factors);
    const section = h('div', { class: 'predictor' },
      h('h3', {}, `${m.file}: ${m.backends.join(', ')} jobs on ${m.devices.join(', ')}`),
      h('p', {}, `Trained on ${m.rows} measured jobs: per cost ${m.folds} general vector machines, each with one fold held out; `
        + `the range given with each prediction held ${Math.round(m.coverage * 100)} % of the held-out jobs.`),
      h('p', { class: 'hint' }, `Ranges around the median: ${costs.map(([k, c]) => `${k.replaceAll('_', ' ')} ${factor(c.interval_factors[0])} to ${factor(c.interval_factors[1])}`).join('; ')}.`),
      box);
    requestAnimationFrame(() => disposers.push(predictorCharts(box, m)));
    return section;
  });
}

// The last retraining, per backend: what it learnt from and what it decided.
function retrainText(r) {
  const every = r.every > 0 ? `Retrains after every ${r.every} finished jobs of a backend, or when asked.`
    : 'Retrains only when asked.';
  const paces = Object.entries(r.pace || {}).map(([backend, p]) =>
    `${backend} ${p.factor.toFixed(2)}× (its last ${p.jobs} jobs)`);
  const pace = paces.length ? ` Time prices follow the machine's pace, measured over predicted: ${paces.join(', ')}.` : '';
  if (r.running) return [`Retraining now. ${every}${pace}`];
  if (!r.last?.backends) return [`Not retrained since the server started. ${every}${pace}`];
  const pct = (e) => (e ? Object.entries(e).map(([k, v]) => `${k.replaceAll('_', ' ')} ${v.toFixed(1)} %`).join(', ') : '');
  const parts = Object.entries(r.last.backends).map(([backend, b]) => {
    const rows = `${b.rows.base} logged and ${b.rows.service} service jobs to train on, ${b.rows.held_out} held out`;
    const errs = Object.keys(b.candidate_errors || {}).length ? ` Held-out error: candidate ${pct(b.candidate_errors)}`
      + `${b.current_errors ? `; in use ${pct(b.current_errors)}` : ''}.` : '';
    return h('span', { class: 'retrain-backend' }, h('strong', {}, `${backend}: `), `${b.decision} (${rows}).${errs} `);
  });
  return [`Last retraining ${fmtDate(r.last.started_at)}, ${fmtSeconds(r.last.took_s)}: `, ...parts, every + pace];
}

// How far the predictions given at submission were from what the jobs measured,
// over the rows shown: memory (every job has one) and time (where a model gave one).
function memorySummary(rows) {
  const off = (pairs) => {
    const errs = pairs.map(([p, m]) => Math.abs(p - m) / m);
    const mean = errs.reduce((a, b) => a + b, 0) / errs.length;
    return `off by ${(mean * 100).toFixed(0)} % on average (largest ${(Math.max(...errs) * 100).toFixed(0)} %) over ${pairs.length} job${pairs.length === 1 ? '' : 's'}`;
  };
  const memory = rows.map((l) => [l.predicted?.peak_host_bytes?.value, l.measured?.peak_host_bytes]).filter(([p, m]) => p > 0 && m > 0);
  const time = rows.map((l) => [l.predicted?.total_time_s?.value, l.measured?.total_s]).filter(([p, m]) => p > 0 && m > 0);
  if (!memory.length) return h('p', { class: 'hint' }, 'No finished job has both a predicted and a measured peak memory yet.');
  return h('p', {}, `Predicted at submission against measured, in the rows shown: peak memory ${off(memory)}`
    + `${time.length ? `; total time ${off(time)}` : '; no job had its time predicted'}.`);
}

function rowOf(l) {
  const i = l.inputs || {};
  const m = l.measured || {};
  const p = l.predicted || {};
  const td = (v, numeric = true) => h('td', { class: numeric ? 'num' : undefined }, v ?? '—');
  return h('tr', {},
    h('th', { scope: 'row' }, String(l.id)),
    td(fmtDate(l.created_at), false),
    // Not a link: GET /api/v1/jobs/{id} answers only the job's owner.
    td(h('code', { title: l.job_id }, `${l.job_id.slice(0, 8)}…`), false),
    td(i.particles?.toLocaleString()),
    td(i.triangles?.toLocaleString()),
    td(i.method, false),
    td(i.backend ? `${i.backend}${i.threads ? ` × ${i.threads}` : ''}` : undefined, false),
    td(fmtSeconds(m.total_s)),
    td(Number.isFinite(p.total_time_s?.value) ? fmtSeconds(p.total_time_s.value) : 'not predicted'),
    td(fmtBytes(m.peak_host_bytes)),
    td(fmtBytes(p.peak_host_bytes?.value)));
}
