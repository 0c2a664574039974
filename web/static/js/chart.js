// stats.csv (one row per output frame; columns in job/stats_file.cpp) as
// uPlot line charts: contacts and energy over time, and a chart of any other
// group of columns picked from a list.
import uPlot from '/ui/vendor/uplot/uPlot.esm.js';
import { h, field } from './dom.js';

const LABELS = {
  active: 'moving', waiting: 'not yet poured', held: 'due, place taken', escaped: 'escaped', invalid: 'invalid', touching_wall: 'touching the wall',
  wall_contacts: 'wall contacts', particle_contacts: 'particle contacts',
  kinetic_J: 'kinetic', elastic_J: 'elastic', potential_J: 'potential', total_J: 'total',
  max_speed_m_s: 'top speed (m/s)', max_overlap: 'largest overlap',
  substeps: 'time steps', wall_ms: 'compute time (ms)',
};
export const MAIN = [
  ['Contacts', ['wall_contacts', 'particle_contacts', 'touching_wall']],
  ['Energy (J)', ['kinetic_J', 'elastic_J']],
];
export const MORE = [
  ['Particles', ['active', 'waiting', 'held', 'escaped', 'invalid']],
  ['Potential and total energy (J)', ['potential_J', 'total_J']],
  ['Speed and overlap', ['max_speed_m_s', 'max_overlap']],
  ['Work per frame', ['substeps', 'wall_ms']],
];
// Colour-blind-safe (Okabe–Ito), dark enough on white.
const COLOURS = ['#0072b2', '#d55e00', '#009e73', '#cc79a7', '#8a6d00'];
const compact = new Intl.NumberFormat('en', { notation: 'compact', maximumSignificantDigits: 3 });
const tick = (u, values) => values.map((v) => (v === null ? '' : Math.abs(v) >= 1e4 ? compact.format(v) : String(+v.toPrecision(4))));

// {columns: [...], rows: [[numbers]]} from CSV text with a header line.
export function parseCsv(text) {
  const lines = text.trim().split(/\r?\n/);
  const columns = lines.shift().split(',').map((c) => c.trim());
  const rows = lines.filter((l) => l.trim()).map((l) => l.split(',').map(Number));
  return { columns, rows };
}

// Sums a stats table for the key figures: the largest value of a column.
export function columnMax(table, name) {
  const i = table.columns.indexOf(name);
  if (i < 0 || !table.rows.length) return null;
  return Math.max(...table.rows.map((r) => r[i]).filter(Number.isFinite));
}

function lineChart(box, table, title, names) {
  const { columns, rows } = table;
  const col = (name) => rows.map((r) => r[columns.indexOf(name)]);
  const xName = columns.includes('time_s') ? 'time_s' : columns[0];
  const plotBox = h('div', { class: 'chart', 'aria-hidden': 'true' });  // a picture: the caption and the CSV carry it
  box.replaceChildren(plotBox);
  const width = () => Math.max(260, box.clientWidth || 500);
  const plot = new uPlot({
    title, width: width(), height: 260,
    scales: { x: { time: false } },
    axes: [{ label: 'simulated time (s)', values: tick }, { values: tick, size: 56 }],
    series: [{ label: 'time (s)' }, ...names.map((n, i) => ({ label: LABELS[n] || n, stroke: COLOURS[i % COLOURS.length], width: 2 }))],
  }, [col(xName), ...names.map(col)], plotBox);
  const observer = new ResizeObserver(() => plot.setSize({ width: width(), height: 260 }));
  observer.observe(box);
  return () => { observer.disconnect(); plot.destroy(); };
}

// The charts in `box`; answers a dispose function.
export function statsCharts(box, csvText, statsUrl) {
  const table = parseCsv(csvText);
  const present = (groups) => groups.map(([t, names]) => [t, names.filter((n) => table.columns.includes(n))])
    .filter(([, names]) => names.length);
  const main = present(MAIN);
  const more = present(MORE);
  const disposers = [];
  const figure = (title, names) => {
    const plotBox = h('div');
    const caption = h('figcaption', { class: 'hint' },
      `${title} over ${table.rows.length} frames: ${names.map((n) => LABELS[n] || n).join(', ')}.`);
    return { el: h('figure', { class: 'chart-figure' }, plotBox, caption), plotBox, title, names };
  };
  const figures = main.map(([t, names]) => figure(t, names));
  const picker = h('select', {}, more.map(([title], i) => h('option', { value: String(i) }, title)));
  const moreBox = h('div');
  let disposeMore = null;
  box.replaceChildren(
    h('div', { class: 'chart-grid' }, figures.map((f) => f.el)),
    more.length ? h('div', { class: 'more-chart' }, field('More from the statistics', picker), moreBox) : null,
    h('p', { class: 'hint' }, 'Click a name under a chart to hide or show its line. The numbers are in ',
      h('a', { href: statsUrl, download: 'stats.csv' }, 'stats.csv'), '.'));
  for (const f of figures) disposers.push(lineChart(f.plotBox, table, f.title, f.names));
  const drawMore = () => {
    disposeMore?.();
    const [title, names] = more[Number(picker.value)];
    disposeMore = lineChart(moreBox, table, title, names);
  };
  if (more.length) { picker.addEventListener('change', drawMore); drawMore(); }
  return () => { disposers.forEach((d) => d()); disposeMore?.(); };
}

// A job cost model's training (GET /api/v1/admin/predictor): the loss per epoch
// (train and held-out fold, log scale) and the held-out predictions of total time
// against the measured times, log-log with the line of perfect prediction.
// Answers a dispose function.
export function predictorCharts(box, model) {
  const disposers = [];
  const chart = (opts, data) => {
    const plotBox = h('div', { class: 'chart', 'aria-hidden': 'true' });
    box.append(plotBox);
    const width = () => Math.max(260, Math.min(520, box.clientWidth || 500));
    const plot = new uPlot({ width: width(), height: 260, ...opts }, data, plotBox);
    const observer = new ResizeObserver(() => plot.setSize({ width: width(), height: 260 }));
    observer.observe(box);
    disposers.push(() => { observer.disconnect(); plot.destroy(); });
  };
  const curve = model.curve || [];
  if (curve.length) {
    chart({
      title: `Loss per epoch (${model.file})`,
      scales: { x: { time: false }, y: { distr: 3 } },
      axes: [{ label: 'epoch', values: tick }, { label: 'mean squared error (scaled)', values: tick, size: 64 }],
      series: [{ label: 'epoch' },
        { label: 'training rows', stroke: COLOURS[0], width: 2 },
        { label: 'held-out fold', stroke: COLOURS[1], width: 2 }],
    }, [curve.map((e) => e[0]), curve.map((e) => e[1]), curve.map((e) => e[2])]);
  }
  const held = (model.costs?.total_s?.held_out || []).filter(([m, p]) => m > 0 && p > 0)
    .sort((a, b) => a[0] - b[0]);
  if (held.length) {
    const lo = held[0][0], hi = held[held.length - 1][0];
    chart({
      title: 'Total time: held-out prediction against measured (s)',
      scales: { x: { time: false, distr: 3 }, y: { distr: 3 } },
      axes: [{ label: 'measured (s)', values: tick }, { label: 'predicted (s)', values: tick, size: 64 }],
      series: [{ label: 'measured' },
        { label: 'predicted', stroke: COLOURS[0], width: 0, points: { show: true, size: 5, fill: COLOURS[0] } },
        { label: 'perfect', stroke: COLOURS[4], width: 1, dash: [4, 4], points: { show: false }, spanGaps: true }],
    }, [held.map((r) => r[0]), held.map((r) => r[1]),
      held.map((r) => (r[0] === lo || r[0] === hi ? r[0] : null))]);
  }
  return () => disposers.forEach((d) => d());
}
