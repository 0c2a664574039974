// Administrators: the run log (GET /api/v1/admin/logs), one row per finished
// job with its inputs and measured against predicted cost, paged by id; the
// algorithms (GET /api/v1/algorithms); the cost predictor's training, which
// has no API yet.
import { get } from '../api.js';
import { h, tableBox, errorBox, showError, fmtBytes, fmtSeconds, fmtDate } from '../dom.js';
import { algorithmsTable } from './methods.js';

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
      h('div', { class: 'alert note' },
        h('strong', {}, 'Not available yet. '),
        'The job cost model is not trained on this server, and the service has no API for its training ',
        '(loss curves, predicted against measured time). Until it has, jobs are priced by the engine’s formula for memory, and their time is not predicted.'),
      summary),
    h('section', { 'aria-labelledby': 'alg-h' },
      h('h2', { id: 'alg-h' }, 'Algorithms'),
      algorithms ? algorithmsTable(algorithms) : h('p', {}, 'The list could not be read.')));
  await load();
}

// How far the formula's memory estimate was from the measured peak, over the rows shown.
function memorySummary(rows) {
  const pairs = rows.map((l) => [l.predicted?.peak_host_bytes?.value, l.measured?.peak_host_bytes])
    .filter(([p, m]) => p > 0 && m > 0);
  if (!pairs.length) return h('p', { class: 'hint' }, 'No finished job has both a predicted and a measured peak memory yet.');
  const errs = pairs.map(([p, m]) => Math.abs(p - m) / m);
  const mean = errs.reduce((a, b) => a + b, 0) / errs.length;
  return h('p', {}, `Memory, the formula against the measured peak over the ${pairs.length} job${pairs.length === 1 ? '' : 's'} shown: `
    + `off by ${(mean * 100).toFixed(0)} % on average (largest ${(Math.max(...errs) * 100).toFixed(0)} %).`);
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
    td(typeof p.total_time_s === 'number' ? fmtSeconds(p.total_time_s) : 'not predicted'),
    td(fmtBytes(m.peak_host_bytes)),
    td(fmtBytes(p.peak_host_bytes?.value)));
}
