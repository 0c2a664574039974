// Methods: how the engine finds contacts (GET /api/v1/algorithms, public), and
// the study's charts (docs/study.md), which scripts/install-web.sh copies from
// docs/img/study/ into /ui/study/: speed against accuracy per scene, where the
// dynamics break, and the paper's figures redrawn.
import { get } from '../api.js';
import { h, tableBox } from '../dom.js';

// The algorithms as two tables: detection methods, and traversals.
export function algorithmsTable(a) {
  const table = (caption, list, note) => tableBox(caption, h('table', {},
    h('caption', {}, caption),
    h('thead', {}, h('tr', {}, h('th', { scope: 'col' }, 'Name'), h('th', { scope: 'col' }, 'What it does'))),
    h('tbody', {}, (list || []).map((m) => h('tr', {},
      h('th', { scope: 'row' }, h('code', {}, m.name)),
      h('td', {}, m.description, note && note(m) ? h('span', { class: 'hint' }, ` ${note(m)}`) : null))))));
  return h('div', { class: 'stack' },
    table('Detection methods', a.methods,
      (m) => (m.name === 'reference' ? '(Used to check the others; jobs cannot choose it.)'
        : m.jobs === false ? '(Jobs cannot choose it yet.)' : '')),
    table('Traversals (how the GPU walks the grid)', a.traversals));
}

const SETS = [['gpu', 'Full study, NVIDIA H200'], ['cpu', 'Quick study, 2-core CPU']];
const PAPER = [['paper_table4', 'The paper\u2019s Table 4 and Fig. 11: time per frame against particles, ours beside the paper\u2019s'],
  ['paper_fig12', 'Fig. 12: wall against particle traversal'],
  ['paper_fig13', 'Fig. 13: time against triangles after division, with the paper\u2019s linear fits'],
  ['paper_fig14', 'Fig. 14: time against grid length']];
const STABILITY = [['stability_bounce', 'A ball bouncing obliquely off a floor'],
  ['stability_thin_wall', 'A ball fired at a slab thinner than its radius'],
  ['stability_box', '27 elastic particles in a box'],
  ['stability_box_pairs', 'The same with particle\u2013particle contacts']];

async function summaryOf(set) {
  try {
    const r = await fetch(`/ui/study/${set}/summary.json`);
    return r.ok ? await r.json() : null;
  } catch { return null; }
}

// A figure that removes itself when its chart was not part of this study.
function figure(src, caption) {
  const img = h('img', { src, alt: caption, loading: 'lazy', class: 'chart-img' });
  const fig = h('figure', { class: 'study-fig' }, img, h('figcaption', {}, caption));
  img.addEventListener('error', () => fig.remove());
  return fig;
}

// One Pareto chart at a time, chosen by scene and placement, with what auto picked.
function paretoPicker(set, groups) {
  const label = (g) => `${g.scene}, ${g.placement === 'near' ? 'within 1e-4 r of touching' : 'uniform'} (${g.particles.toLocaleString()} particles, ${g.backend})`;
  const pick = h('select', { id: `pareto-${set}` }, groups.map((g, i) => h('option', { value: String(i) }, label(g))));
  const slot = h('div', {});
  const show = () => {
    const g = groups[Number(pick.value)];
    const a = g.auto;
    const verdict = !a ? 'The automatic choice was not measured here.'
      : `method auto picked ${a.method}/${a.traversal}${a.grid_factor ? ` with grid ${a.grid_factor} r_max` : ''} (${a.frame_ms.toPrecision(3)} ms, exact): `
        + (g.auto_on_front ? 'on the Pareto front.'
          : g.auto_on_front_beyond_repeat ? 'on the Pareto front within its measurements\u2019 spread (no setting was faster in every measurement).'
            : g.auto_on_front_within_5pct ? 'within 5 % of the front, beyond its measurements\u2019 spread.' : 'off the front.');
    slot.replaceChildren(
      figure(`/ui/study/${set}/pareto_${g.backend}_${g.scene}_${g.placement}.png`,
        `Time per frame against contact error: ${label(g)}`),
      h('p', { class: 'hint' }, verdict));
  };
  // Open on the paper's wall1 with particles at the surface, where the methods differ most.
  const first = groups.findIndex((g) => g.scene === 'wall1' && g.placement === 'near');
  if (first >= 0) pick.value = String(first);
  pick.addEventListener('change', show);
  show();
  return h('div', { class: 'stack' }, h('label', { for: `pareto-${set}` }, 'Scene'), pick, slot);
}

async function studySection() {
  const parts = [];
  for (const [set, title] of SETS) {
    const summary = await summaryOf(set);
    if (!summary) continue;
    const groups = (summary.detect || []).filter((g) => g.particles);
    parts.push(h('section', { 'aria-labelledby': `study-${set}-h` },
      h('h3', { id: `study-${set}-h` }, title),
      groups.length ? paretoPicker(set, groups) : null,
      h('h4', {}, 'Where the dynamics break'),
      h('div', { class: 'study-grid' }, STABILITY.map(([f, c]) => figure(`/ui/study/${set}/${f}.png`, c))),
      h('h4', {}, 'The paper\u2019s figures, redrawn'),
      h('div', { class: 'study-grid' }, PAPER.map(([f, c]) => figure(`/ui/study/${set}/${f}.png`, c)))));
  }
  if (!parts.length) {
    return [h('div', { class: 'alert note' }, h('strong', {}, 'Not available yet. '),
      'The study\u2019s charts appear here once scripts/install-web.sh has copied them from docs/img/study/.')];
  }
  return [h('p', {}, 'Every method is exact (float, with the pairs near touching decided again in double); '
    + 'float precision alone is faster by a hair and wrong near touching. bin with the particle traversal is the '
    + 'fastest exact setting on every wall studied; method auto times the grid lengths on the scene\u2019s own '
    + 'particles and keeps the fastest.'), ...parts];
}

export async function render(main) {
  const a = await get('/api/v1/algorithms');
  main.append(
    h('h1', {}, 'Methods'),
    h('p', { class: 'lead' }, 'Each time step, every particle near the wall is tested against the wall\u2019s triangles. '
      + 'The methods differ in how they cut the wall into pieces first, which trades speed against accuracy.'),
    h('section', { 'aria-labelledby': 'alg-h' }, h('h2', { id: 'alg-h' }, 'The algorithms'), algorithmsTable(a)),
    h('section', { 'aria-labelledby': 'study-h' }, h('h2', { id: 'study-h' }, 'The study: speed against accuracy'),
      ...(await studySection())));
}
