// Methods: how the engine finds contacts (GET /api/v1/algorithms, public), and
// the study's charts once the service publishes them (it does not yet).
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
      (m) => (m.name === 'reference' ? '(Used to check the others; jobs cannot choose it.)' : '')),
    table('Traversals (how the GPU walks the grid)', a.traversals));
}

export async function render(main) {
  const a = await get('/api/v1/algorithms');
  main.append(
    h('h1', {}, 'Methods'),
    h('p', { class: 'lead' }, 'Each time step, every particle near the wall is tested against the wall’s triangles. '
      + 'The methods differ in how they cut the wall into pieces first, which trades speed against accuracy.'),
    h('section', { 'aria-labelledby': 'alg-h' }, h('h2', { id: 'alg-h' }, 'The algorithms'), algorithmsTable(a)),
    h('section', { 'aria-labelledby': 'study-h' }, h('h2', { id: 'study-h' }, 'The study'),
      h('div', { class: 'alert note' }, h('strong', {}, 'Not available yet. '),
        'The charts of speed against accuracy, and of where each method fails, appear here once the study has run '
        + 'and the service publishes its results.')));
}
