// One job: its progress while it runs; then the video, key figures, the stats
// charts, the cost against the prediction, the downloads, sharing, cancel and
// delete.
import { get, post, del } from '../api.js';
import { h, tableBox, errorBox, showError, fmtBytes, fmtSeconds, fmtDate, wallLabel } from '../dom.js';
import { statsCharts, parseCsv, columnMax } from '../chart.js';
import { POLL_MS, isActive, progressCell, stateText } from './jobs.js';

export async function render(main, ctx, id) {
  const error = errorBox();  // reading the job: cleared by the next poll that reads it
  const actionError = errorBox();  // a cancel's or delete's: stays until the next action
  const title = h('h1', {}, `Job ${id}`);
  const subtitle = h('p', { class: 'hint' }, `Job ${id}`);
  const head = h('div', { class: 'card' });
  const actions = h('div', { class: 'actions' });
  const body = h('div');
  const live = h('p', { class: 'visually-hidden', 'aria-live': 'polite' });
  main.append(title, subtitle, error, head, actions, actionError, live, body);
  let timer = null;
  let stopped = false;
  let shownDone = false;
  let disposeChart = null;
  let lastState = null;
  let modelsById = new Map();
  try { modelsById = new Map((await get('/api/v1/models')).map((m) => [m.id, m])); } catch { /* ids are shown instead */ }

  async function refresh() {
    let j;
    try { j = await get(`/api/v1/jobs/${encodeURIComponent(id)}`); } catch (e) {
      showError(error, e);
      if (e.status !== 404 && !stopped) timer = setTimeout(refresh, POLL_MS * 2);
      return;
    }
    if (stopped) return;
    showError(error, null);
    if (lastState && lastState !== j.state) live.textContent = `The job is ${j.state}.`;
    // The buttons are made again only when the state changes: replaced every
    // poll, a focused button was lost under the keyboard (and a click, now and then).
    const changed = lastState !== j.state;
    lastState = j.state;
    const s = j.scene || {};
    title.textContent = `${wallLabel(s.wall, modelsById)}: ${s.particles?.count?.toLocaleString() ?? '?'} particles`;
    document.title = `${title.textContent} — Collidoscope`;
    showHead(j);
    if (changed) showActions(j);
    if (j.state === 'done' && !shownDone) { shownDone = true; await showResult(j); }
    if (isActive(j)) timer = setTimeout(refresh, POLL_MS);
  }

  // How the wall moved, in words (the scene's wall_motion), or null for a still wall.
  function motionText(m) {
    if (!m || !m.kind || m.kind === 'none') return null;
    const axis = (a) => {
      if (!Array.isArray(a)) return 'z';
      const names = ['x', 'y', 'z'];
      const k = a.findIndex((c) => c !== 0);
      return a.filter((c) => c !== 0).length === 1 ? names[k] : `(${a.join(', ')})`;
    };
    const num = (x) => Number(Number(x).toPrecision(3)).toLocaleString();
    const what = Number.isInteger(m.part) && m.part > 0 ? `part ${m.part} ` : '';
    if (m.kind === 'rotate') {
      const rpm = Number.isFinite(m.rpm) ? m.rpm : (m.angular_speed ?? 0) * 60 / (2 * Math.PI);
      return `${what}turns ${num(rpm)} a minute about ${axis(m.axis)}`;
    }
    if (m.kind === 'oscillate') return `${what}shakes ${num(m.amplitude ?? 0)} at ${num(m.frequency ?? 0)} Hz along ${axis(m.axis)}`;
    if (m.kind === 'translate') return `moves at (${(m.velocity || []).map(num).join(', ')}) per second`;
    return m.kind;
  }

  function showHead(j) {
    const s = j.scene || {};
    const fact = (k, v) => h('div', {}, h('dt', {}, k), h('dd', {}, v));
    const radius = Array.isArray(s.particles?.radius) ? s.particles.radius.join(' to ') : (s.particles?.radius ?? 'default');
    head.replaceChildren(...[
      h('dl', { class: 'facts-row' },
        fact('State', stateText(j)),
        isActive(j) ? fact('Progress', progressCell(j)) : null,
        fact('Wall', wallLabel(s.wall, modelsById)),
        motionText(s.wall_motion) ? fact('Wall motion', motionText(s.wall_motion)) : null,
        fact('Particles', `${s.particles?.count?.toLocaleString() ?? '—'}, radius ${radius}`),
        fact('Placement', s.placement?.kind ?? 'fill'),
        s.contact_model === 'hertz_mindlin' ? fact('Contact law', 'Hertz–Mindlin') : null,
        fact('Simulated', `${s.duration ?? '—'} s at ${s.fps ?? '—'} frames/s`),
        fact('Method', `${s.method ?? 'bin'}${s.backend && s.backend !== 'auto' ? `, ${s.backend}` : ''}`),
        j.scheduler ? fact('Runs on', `the cluster (Slurm job ${j.scheduler.job_id})`) : null,
        fact('Submitted', fmtDate(j.created_at)),
        j.finished_at ? fact('Finished', fmtDate(j.finished_at)) : null),
      j.reused_from ? h('p', { class: 'alert note' }, `An identical scene ran before (job ${j.reused_from}): its result is shown, not run again.`) : null,
      j.error ? h('p', { class: 'alert error' }, `The job ${j.state === 'failed' ? 'failed' : 'ended'}: ${j.error}`) : null,
    ].filter(Boolean));
  }

  function showActions(j) {
    const buttons = [];
    if (isActive(j)) {
      buttons.push(h('button', { type: 'button', class: 'secondary', onclick: async () => {
        showError(actionError, null);
        try { await post(`/api/v1/jobs/${j.id}/cancel`); clearTimeout(timer); refresh(); } catch (e) { showError(actionError, e); }
      } }, 'Cancel job'));
    }
    if (j.state !== 'running') {
      buttons.push(h('button', { type: 'button', class: 'danger', onclick: async () => {
        if (!confirm(`Delete job ${j.id} and its files? Share links to it stop working.`)) return;
        showError(actionError, null);
        try { await del(`/api/v1/jobs/${j.id}`); ctx.go('#/jobs'); } catch (e) { showError(actionError, e); }
      } }, 'Delete job'));
    }
    buttons.push(h('a', { class: 'button secondary', href: '#/jobs' }, 'All jobs'));
    actions.replaceChildren(...buttons);
  }

  async function showResult(j) {
    const L = j.links || {};
    const s = j.scene || {};
    const video = h('video', { controls: true, preload: 'metadata', playsinline: true, loop: true,
      poster: L.poster, 'aria-describedby': 'video-desc' },
      L.webm ? h('source', { src: L.webm, type: 'video/webm' }) : null,
      L.mp4 ? h('source', { src: L.mp4, type: 'video/mp4' }) : null,
      h('p', {}, 'This browser does not play the video here; ', L.mp4 ? h('a', { href: L.mp4 }, 'download the MP4') : 'see the files below', '.'));
    // A small render is shown larger, but not blown up past twice its size.
    video.addEventListener('loadedmetadata', () => {
      if (video.videoWidth) video.style.maxWidth = `${Math.max(480, Math.min(2 * video.videoWidth, 1280))}px`;
    });
    const desc = h('p', { id: 'video-desc', class: 'hint' },
      `Animation of ${s.particles?.count ?? 'the'} particles (${s.placement?.kind ?? 'fill'}) colliding with ${wallLabel(s.wall, modelsById)}`
      + `${motionText(s.wall_motion) ? `, ${s.wall_motion.part > 0 ? 'whose' : 'which'} ${motionText(s.wall_motion)}` : ''}, `
      + `${s.duration ?? '?'} simulated seconds; colour shows each particle's speed; no sound.`);
    const figures = h('dl', { class: 'figures' });
    const chartBox = h('div');
    const files = h('div');
    const cost = h('div');
    body.replaceChildren(
      h('div', { class: 'split wide-left' },
        h('section', { 'aria-labelledby': 'video-h' }, h('h2', { id: 'video-h' }, 'Video'), video, desc),
        h('section', { 'aria-labelledby': 'fig-h' }, h('h2', { id: 'fig-h' }, 'Key figures'), figures)),
      shareSection(j),
      h('section', { 'aria-labelledby': 'stats-h' }, h('h2', { id: 'stats-h' }, 'Over time'), chartBox),
      h('div', { class: 'split' },
        h('section', { 'aria-labelledby': 'cost-h' }, h('h2', { id: 'cost-h' }, 'Cost: predicted and measured'), cost),
        h('section', { 'aria-labelledby': 'files-h' }, h('h2', { id: 'files-h' }, 'Downloads'), files)),
      h('details', {}, h('summary', {}, 'The scene as submitted'), h('pre', {}, JSON.stringify(j.scene, null, 2))));
    cost.append(costTable(j));

    const [manifest, csv] = await Promise.all([
      get(L.manifest).catch((e) => { files.replaceChildren(h('p', { class: 'alert error' }, `The file list could not be read: ${e.message}`)); return null; }),
      fetch(L.stats, { credentials: 'same-origin' }).then(async (r) => {
        if (!r.ok) throw new Error(`${r.status} ${r.statusText}`);
        return r.text();
      }).catch((e) => { chartBox.replaceChildren(h('p', { class: 'alert error' }, `The statistics could not be read: ${e.message}`)); return null; }),
    ]);
    if (stopped) return;
    const table = csv ? parseCsv(csv) : null;
    showFigures(figures, j, manifest, table);
    if (csv) disposeChart = statsCharts(chartBox, csv, L.stats);
    if (manifest) files.replaceChildren(await downloads(L, manifest));
  }

  await refresh();
  return () => { stopped = true; clearTimeout(timer); disposeChart?.(); };
}

// The numbers a class looks at first, from the manifest and the statistics.
function showFigures(dl, j, m, table) {
  const c = j.cost || {};
  const n = (v) => (Number.isFinite(v) ? v.toLocaleString() : '—');
  const max = (name) => (table ? columnMax(table, name) : null);
  const speed = max('max_speed_m_s');
  const items = [
    ['Particles', n(m?.particles ?? j.scene?.particles?.count)],
    ['Escaped', n(m?.escaped)],
    ['Most wall contacts at once', n(max('wall_contacts'))],
    ['Most particle contacts at once', j.scene?.particle_contacts ? n(max('particle_contacts')) : 'not simulated'],
    ['Top speed', Number.isFinite(speed) ? `${+speed.toPrecision(3)} m/s` : '—'],
    ['Frames', n(m?.frames ?? c.frames)],
    ['Time steps', n(c.steps)],
    ['Wall triangles', n(m?.triangles)],
    ['Computed in', fmtSeconds(c.total_s)],
    ['Ran on', m?.backend ? `${m.backend.toUpperCase()}${m.threads ? `, ${m.threads} thread${m.threads === 1 ? '' : 's'}` : ''}` : '—'],
  ];
  dl.replaceChildren(...items.map(([k, v]) => h('div', {}, h('dt', {}, k),
    h('dd', { class: /\d/.test(v) ? 'big' : 'big words' }, v))));
  if (m?.notes?.length) dl.after(h('ul', { class: 'hint' }, m.notes.map((t) => h('li', {}, t))));
}

function costTable(j) {
  const p = j.prediction || {};
  const c = j.cost || {};
  const ratio = (pred, meas) => (pred > 0 && meas > 0 ? `${(meas / pred).toFixed(meas / pred < 10 ? 2 : 0)}×` : '—');
  const row = (what, predicted, measured, r = '—') => h('tr', {}, h('th', { scope: 'row' }, what),
    h('td', { class: 'num' }, predicted || '—'), h('td', { class: 'num' }, measured || '—'), h('td', { class: 'num' }, r));
  const predBytes = p.peak_host_bytes?.value ?? (typeof p.peak_host_bytes === 'number' ? p.peak_host_bytes : null);
  const predTime = p.total_time_s?.value ?? (typeof p.total_time_s === 'number' ? p.total_time_s : null);
  return h('div', {}, tableBox('Cost, predicted and measured', h('table', {},
    h('thead', {}, h('tr', {}, h('th', { scope: 'col' }, 'Figure'), h('th', { scope: 'col', class: 'num' }, 'Predicted'),
      h('th', { scope: 'col', class: 'num' }, 'Measured'), h('th', { scope: 'col', class: 'num' }, 'Measured ÷ predicted'))),
    h('tbody', {},
      row('Peak memory', fmtBytes(predBytes), fmtBytes(c.peak_host_bytes), ratio(predBytes, c.peak_host_bytes)),
      row('Total time', predTime === null ? 'not predicted' : fmtSeconds(predTime), fmtSeconds(c.total_s), ratio(predTime, c.total_s)),
      row('Simulation', '', fmtSeconds(c.simulate_s)),
      row('Rendering', '', fmtSeconds(c.render_s)),
      // The manifest counts the initial frame too; the prediction's inputs count those after it.
      row('Frames', p.inputs?.frames == null ? '' : (p.inputs.frames + 1).toLocaleString(), c.frames?.toLocaleString()),
      row('Time steps', '', c.steps?.toLocaleString())))),
    p.note ? h('p', { class: 'hint' }, `${p.note[0].toUpperCase()}${p.note.slice(1)}.`) : null);
}

// The names of the files in a folder the manifest counts (it lists folders as
// one entry): snapshots and VTP files are one per frame; frame images are
// every k-th frame, k a server setting (10 unless changed), checked by asking
// for the last one.
async function folderFiles(base, a, manifest) {
  const pad = (i) => String(i).padStart(6, '0');
  if (a.path === 'frames/') return Array.from({ length: a.count }, (_, i) => `frames/frame_${pad(i)}.snap`);
  if (a.path === 'render/frames/') {
    const frames = manifest.frames || a.count;
    let every = 1;
    if (a.count > 1) {
      const fits = (k) => Math.ceil(frames / k) === a.count;
      every = fits(10) ? 10 : [...Array(frames).keys()].map((k) => k + 1).find(fits) || 0;
    }
    if (!every) return null;
    const names = Array.from({ length: a.count }, (_, i) => `render/frames/frame_${pad(i * every)}.png`);
    const last = await fetch(base + names[names.length - 1], { headers: { Range: 'bytes=0-0' }, credentials: 'same-origin' }).catch(() => null);
    return last && last.ok ? names : null;
  }
  return null;
}

async function downloads(L, manifest) {
  const base = L.manifest.replace(/result\.json$/, '');
  const arts = manifest.artifacts || [];
  const byPath = new Map(arts.map((a) => [a.path, a]));
  const link = (path, text) => {
    const a = byPath.get(path);
    return a ? h('li', {}, h('a', { href: base + path, download: path.split('/').pop() }, text), ` (${fmtBytes(a.bytes)})`) : null;
  };
  const folder = async (path, text) => {
    const a = byPath.get(path);
    if (!a) return null;
    const names = await folderFiles(base, a, manifest);
    const summary = `${text}: ${a.count.toLocaleString()} file${a.count === 1 ? '' : 's'}, ${fmtBytes(a.bytes)}`;
    if (!names) return h('li', {}, summary);
    return h('li', {}, h('details', {}, h('summary', {}, summary),
      h('ul', { class: 'file-list' }, names.map((n) => h('li', {}, h('a', { href: base + n, download: n.split('/').pop() }, n.split('/').pop()))))));
  };
  // ParaView: the collection file names each frame's .vtp.
  let paraview = null;
  if (byPath.has('frames.pvd')) {
    let vtps = [];
    try {
      const text = await (await fetch(base + 'frames.pvd', { credentials: 'same-origin' })).text();
      vtps = [...text.matchAll(/file="([^"]+\.vtp)"/g)].map((m) => m[1]).filter((p) => /^[\w./-]+$/.test(p) && !p.includes('..'));
    } catch { /* the collection file alone is still listed */ }
    paraview = h('li', {}, h('a', { href: base + 'frames.pvd', download: 'frames.pvd' }, 'frames.pvd'),
      ` (the collection) and ${vtps.length} frame file${vtps.length === 1 ? '' : 's'}; keep them in a folder vtp/ beside it.`,
      vtps.length ? h('details', {}, h('summary', {}, 'The .vtp files'),
        h('ul', { class: 'file-list' }, vtps.map((p) => h('li', {}, h('a', { href: base + p, download: p.split('/').pop() }, p.split('/').pop()))))) : null);
  }
  const group = (heading, items) => {
    const present = items.filter(Boolean);
    return present.length ? [h('h3', {}, heading), h('ul', { class: 'downloads' }, present)] : [];
  };
  const parts = [
    ...group('Video', [link('render/video.mp4', 'MP4 video'), link('render/video.webm', 'WebM video'),
      link('render/loop.gif', 'Animated GIF'), link('render/poster.png', 'Poster image (PNG)')]),
    ...group('Frames', [await folder('render/frames/', 'Frame images (PNG)'), await folder('frames/', 'Particle snapshots (the engine’s format)')]),
    ...group('Data', [link('stats.csv', 'Statistics per frame (CSV)'), paraview,
      link('scene.json', 'The scene as run (JSON)'), link('wall.stl', 'The wall (STL)'),
      h('li', {}, h('a', { href: L.manifest, download: 'result.json' }, 'The manifest (result.json)'))]),
  ];
  return h('div', { class: 'card' }, parts);
}

// Share links: anyone with one sees the result without an account. The
// owner's live links are listed with the job, so one made on an earlier visit
// can still be copied or revoked.
function shareSection(j) {
  const error = errorBox();
  const list = h('div');
  const said = h('p', { role: 'status', class: 'status' });
  const button = h('button', { type: 'button' }, 'Make a share link');
  let shown = 0;
  const relabel = () => { button.textContent = shown ? 'Make another share link' : 'Make a share link'; };
  // One link's card: the URL, the embed code, copy, open and revoke.
  function card(s) {
    const url = h('input', { class: 'share-url', readonly: true, value: s.url, id: `share-url-${s.token}` });
    const snippet = `<iframe src="${s.embed}" width="640" height="360" title="Collidoscope result" allowfullscreen></iframe>`;
    const embed = h('textarea', { class: 'share-url', readonly: true, rows: '3', value: snippet, id: `share-embed-${s.token}` });
    const copy = (input, what) => async () => {
      try {
        await navigator.clipboard.writeText(input.value);
        said.textContent = `${what} copied.`;
      } catch {
        input.focus();
        input.select();
        said.textContent = `${what} selected: press Ctrl+C (⌘C on a Mac) to copy it.`;
      }
    };
    const box = h('div', { class: 'card' });
    const revoke = h('button', { type: 'button', class: 'danger', onclick: async () => {
      showError(error, null);
      try {
        await del(`/api/v1/shares/${s.token}`);
        box.remove();
        shown--;
        relabel();
        said.textContent = 'The link was revoked: it now shows “not found”.';
        button.focus();
      } catch (e) { showError(error, e); }
    } }, 'Revoke link');
    box.append(
      h('label', { for: url.id }, 'Share link', s.created_at ? h('span', { class: 'hint' }, ` (made ${fmtDate(s.created_at)})`) : null), url,
      h('div', { class: 'actions' }, h('button', { type: 'button', onclick: copy(url, 'Link') }, 'Copy link'),
        h('a', { class: 'button secondary', href: s.url, target: '_blank', rel: 'noopener' }, 'Open', h('span', { class: 'visually-hidden' }, ' (new tab)')),
        revoke),
      h('label', { for: embed.id }, 'Embed in a page or slides'), embed,
      h('div', { class: 'actions' }, h('button', { type: 'button', class: 'secondary', onclick: copy(embed, 'Embed code') }, 'Copy embed code')),
      h('p', { class: 'hint' }, s.expires_at ? `The link expires ${fmtDate(s.expires_at)}.` : 'The link does not expire; revoke it to stop it.'));
    return { box, copyLink: copy(url, 'Link') };
  }
  button.addEventListener('click', async () => {
    showError(error, null);
    button.disabled = true;
    try {
      const c = card(await post(`/api/v1/jobs/${j.id}/shares`, {}));
      list.append(c.box);
      shown++;
      relabel();
      await c.copyLink();
    } catch (e) { showError(error, e); }
    button.disabled = false;
  });
  get(`/api/v1/jobs/${j.id}/shares`).then((shares) => {
    for (const s of shares) list.append(card(s).box);
    shown += shares.length;
    relabel();
  }).catch((e) => showError(error, e));
  return h('section', { 'aria-labelledby': 'share-h' }, h('h2', { id: 'share-h' }, 'Share'),
    h('p', {}, 'A link anyone can open without an account, and a player to embed in a page or slides.'), list, button, error, said);
}
