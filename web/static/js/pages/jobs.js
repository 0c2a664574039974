// Your jobs, newest first, with progress; polled while any is queued or running.
import { get, getPage, post, del } from '../api.js';
import { h, tableBox, errorBox, showError, fmtDate, wallLabel } from '../dom.js';

export const POLL_MS = 1500;
// Jobs a page; "Show older jobs" shows another page, up to the API's 1,000 a request.
export const PAGE = 50;
export const MOST_SHOWN = 1000;
export const isActive = (j) => j.state === 'queued' || j.state === 'running';

// A progress bar with its label, for a job in any state.
export function progressCell(j) {
  const pct = Math.round((j.progress || 0) * 100);
  if (!isActive(j)) return h('span', {}, j.state === 'done' ? '100 %' : '—');
  return h('span', {},
    h('progress', { max: '100', value: String(pct), 'aria-label': `Job ${j.id} progress` }),
    ` ${pct} %`, j.stage ? ` · ${j.stage}` : '');
}

export function stateText(j) {
  return h('span', { class: `state state-${j.state}` }, j.state, j.reused_from ? ' (reused)' : '');
}

export async function render(main) {
  const error = errorBox();  // the list's own: cleared by the next poll that reads it
  const actionError = errorBox();  // a cancel's or delete's: stays until the next action
  const tbody = h('tbody');
  const empty = h('p', { hidden: true }, 'No jobs yet. ', h('a', { href: '#/new' }, 'Start one'), '.');
  const live = h('p', { class: 'visually-hidden', 'aria-live': 'polite' });
  let modelsById = new Map();
  let timer = null;
  let stopped = false;
  let lastStates = new Map();
  // Each job's row, kept while its state stays: a poll updates its progress
  // cell alone, so a focused link or button is not replaced under the
  // keyboard (or a click) every tick.
  let rows = new Map();  // id -> {tr, state, progress}
  // The newest `shown` jobs, all read by each poll: a job submitted meanwhile
  // pushes the others down without a gap between pages.
  let shown = PAGE;
  const olderNote = h('p', { class: 'hint', hidden: true },
    `The newest ${MOST_SHOWN.toLocaleString()} jobs are shown; older ones keep their links, and the API lists them (GET /api/v1/jobs, its Link header).`);
  const older = h('button', { type: 'button', class: 'secondary', hidden: true, onclick: async () => {
    const before = tbody.children.length;
    shown = Math.min(shown + PAGE, MOST_SHOWN);
    older.disabled = true;
    await refresh();
    // The last page hides the button: the keyboard goes on at the first job it showed.
    if (older.hidden) tbody.children[before]?.querySelector('a')?.focus();
  } }, 'Show older jobs');

  function row(j) {
    const s = j.scene || {};
    const progress = h('td', {}, progressCell(j));
    const tr = h('tr', {},
      h('th', { scope: 'row' }, h('a', { href: `#/jobs/${j.id}` }, j.id)),
      h('td', {}, fmtDate(j.created_at)),
      h('td', {}, wallLabel(s.wall, modelsById)),
      h('td', { class: 'num' }, s.particles?.count?.toLocaleString() ?? '—'),
      h('td', {}, stateText(j)),
      progress,
      h('td', {}, h('div', { class: 'actions' },
        isActive(j) ? h('button', { type: 'button', class: 'secondary small', 'aria-label': `Cancel job ${j.id}`,
          onclick: async () => {
            showError(actionError, null);
            try { await post(`/api/v1/jobs/${j.id}/cancel`); refresh(); } catch (e) { showError(actionError, e); }
          } }, 'Cancel') : null,
        j.state !== 'running' ? h('button', { type: 'button', class: 'danger small', 'aria-label': `Delete job ${j.id}`,
          onclick: async () => {
            if (!confirm(`Delete job ${j.id} and its files?`)) return;
            showError(actionError, null);
            try { await del(`/api/v1/jobs/${j.id}`); refresh(); } catch (e) { showError(actionError, e); }
          } }, 'Delete') : null)));
    return { tr, state: j.state, progress };
  }

  async function refresh() {
    let jobs, nextPage;
    try {
      ({ items: jobs, next: nextPage } = await getPage(`/api/v1/jobs?limit=${shown}`));
    } catch (e) { older.disabled = false; showError(error, e); schedule(true); return; }
    if (stopped) return;
    older.disabled = false;
    older.hidden = !nextPage || shown >= MOST_SHOWN;
    olderNote.hidden = !(nextPage && shown >= MOST_SHOWN);
    showError(error, null);
    empty.hidden = jobs.length > 0;
    // Screen readers hear when a job ends, not every tick of its progress.
    for (const j of jobs) {
      const before = lastStates.get(j.id);
      if (before && before !== j.state && !isActive(j)) live.textContent = `Job ${j.id} ${j.state}.`;
    }
    lastStates = new Map(jobs.map((j) => [j.id, j.state]));
    const next = new Map();
    for (const j of jobs) {
      const kept = rows.get(j.id);
      if (kept && kept.state === j.state) {
        kept.progress.replaceChildren(progressCell(j));
        next.set(j.id, kept);
      } else {
        next.set(j.id, row(j));
      }
    }
    rows = next;
    const order = jobs.map((j) => next.get(j.id).tr);
    // Rows are put in place only when the list changed (moving a row would blur it).
    if (order.length !== tbody.children.length || order.some((tr, k) => tbody.children[k] !== tr)) {
      tbody.replaceChildren(...order);
    }
    schedule(jobs.some(isActive));
  }
  function schedule(again) {
    clearTimeout(timer);
    if (again && !stopped) timer = setTimeout(refresh, POLL_MS);
  }

  main.append(
    h('h1', {}, 'Jobs'),
    h('div', { class: 'actions' }, h('a', { class: 'button', href: '#/new' }, 'New job')),
    error, actionError, empty, live,
    tableBox('Your jobs', h('table', {},
      h('caption', { class: 'visually-hidden' }, 'Your jobs, newest first'),
      h('thead', {}, h('tr', {}, ['Job', 'Submitted', 'Wall', 'Particles', 'State', 'Progress', 'Actions']
        .map((t) => h('th', { scope: 'col', class: t === 'Particles' ? 'num' : undefined }, t)))),
      tbody)),
    h('div', { class: 'actions' }, older), olderNote);
  try { modelsById = new Map((await get('/api/v1/models')).map((m) => [m.id, m])); } catch { /* ids are shown instead */ }
  await refresh();
  return () => { stopped = true; clearTimeout(timer); };
}
