// The single-page app: hash routes, the signed-in user, the page in <main>.
// Each page module exports render(main, ctx, ...params) and may return a
// cleanup function (stop polling, free the WebGL context) run on leaving it.
import { get, del, setUnauthorizedHandler } from './api.js';
import { h } from './dom.js';
import * as signin from './pages/signin.js';
import * as models from './pages/models.js';
import * as newjob from './pages/newjob.js';
import * as jobs from './pages/jobs.js';
import * as result from './pages/result.js';
import * as admin from './pages/admin.js';
import * as methods from './pages/methods.js';

const main = document.getElementById('main');
const ctx = {
  me: null,  // {id, name, role} once signed in
  meError: null,  // why /me could not be read, when not because the visitor is signed out
  go(hash) { if (location.hash === hash) route(); else location.hash = hash; },
  async signedIn() { await loadMe(); },
  // After signing in: the page the visitor was sent away from, else the jobs.
  afterSignIn() {
    let wanted = null;
    try { wanted = sessionStorage.getItem(WANTED); sessionStorage.removeItem(WANTED); } catch { /* no storage */ }
    ctx.go(wanted && wanted.startsWith('#/') && wanted !== '#/signin' ? wanted : '#/jobs');
  },
};

// Route table: pattern -> [page, needs sign-in, needs admin].
const routes = [
  [/^#\/signin$/, signin, false, false],
  [/^#\/models$/, models, true, false],
  [/^#\/new(?:\?model=(\d+))?$/, newjob, true, false],
  [/^#\/jobs$/, jobs, true, false],
  [/^#\/jobs\/([A-Za-z0-9_-]+)$/, result, true, false],
  [/^#\/admin$/, admin, true, true],
  [/^#\/methods$/, methods, false, false],
];

let cleanup = null;
let routing = 0;
let routedOnce = false;

// Where a signed-out visitor was going: signing in takes them there.
const WANTED = 'collido.wanted';

async function loadMe() {
  try {
    ctx.me = await get('/api/v1/me', { quiet401: true });
  } catch (e) {
    ctx.me = null;
    // Signed out is a 401; anything else (the server down, a 5xx) is not, and
    // the page says so instead of showing a signed-in user the sign-in form.
    ctx.meError = e && e.status === 401 ? null : e;
  }
  if (ctx.me) ctx.meError = null;
  updateHeader();
}

function updateHeader() {
  const signed = !!ctx.me;
  for (const li of document.querySelectorAll('#nav [data-user]')) li.hidden = !signed;
  for (const li of document.querySelectorAll('#nav [data-guest]')) li.hidden = signed;
  document.getElementById('who').hidden = !signed;
  document.getElementById('nav-admin').hidden = !(signed && ctx.me.role === 'admin');
  document.getElementById('who-name').textContent = signed
    ? `Signed in as ${ctx.me.name}${ctx.me.role === 'admin' ? ' (admin)' : ''}` : '';
  for (const a of document.querySelectorAll('#nav a')) {
    const here = location.hash.startsWith(a.getAttribute('href'));
    if (here) a.setAttribute('aria-current', 'page'); else a.removeAttribute('aria-current');
  }
}

async function route() {
  const mine = ++routing;
  if (cleanup) { try { cleanup(); } catch { /* a page's cleanup must not stop navigation */ } }
  cleanup = null;
  if (!location.hash) { location.replace(ctx.me ? '#/jobs' : '#/signin'); return; }
  const hash = location.hash;
  let match = null;
  let entry = null;
  for (const r of routes) {
    match = hash.match(r[0]);
    if (match) { entry = r; break; }
  }
  if (!entry) { ctx.go(ctx.me ? '#/jobs' : '#/signin'); return; }
  const [, page, needsUser, needsAdmin] = entry;
  if (needsUser && !ctx.me && ctx.meError) {
    updateHeader();
    main.replaceChildren(h('h1', {}, 'The server did not answer'),
      h('div', { class: 'alert error', role: 'alert' },
        `Could not tell whether you are signed in: ${ctx.meError.message || ctx.meError}. `,
        h('a', { href: location.hash, onclick: (e) => { e.preventDefault(); loadMe().then(route); } }, 'Try again')));
    return;
  }
  if (needsUser && !ctx.me) {
    try { sessionStorage.setItem(WANTED, hash); } catch { /* no storage: the jobs page */ }
    ctx.go('#/signin');
    return;
  }
  if (page === signin && ctx.me) { ctx.go('#/jobs'); return; }
  updateHeader();
  // Each page renders into a container of its own: a page still loading when
  // the visitor moves on appends into a detached container, not the next page.
  const view = h('div', { class: 'view' });
  main.replaceChildren(view);
  if (needsAdmin && ctx.me.role !== 'admin') {
    view.append(Object.assign(document.createElement('h1'), { textContent: 'Administrators only' }));
    return;
  }
  let result;
  try {
    result = await page.render(view, ctx, ...match.slice(1));
  } catch (e) {
    // A page that fails says so in words, never as a blank page.
    if (mine === routing) {
      view.append(h('div', { class: 'alert error', role: 'alert' },
        `This page could not be shown: ${e.message || e}. Reload to try again.`));
    }
  }
  if (mine !== routing) { if (typeof result === 'function') result(); return; }
  cleanup = typeof result === 'function' ? result : null;
  // Keyboard and screen-reader users land on the new page's heading (not on
  // the first page: a fresh load starts at the top, the skip link first).
  const h1 = main.querySelector('h1');
  if (h1) {
    h1.tabIndex = -1;
    if (routedOnce) h1.focus({ preventScroll: true });
  }
  routedOnce = true;
  document.title = (h1 ? h1.textContent + ' — ' : '') + 'Collidoscope';
}

setUnauthorizedHandler(() => {
  if (ctx.me) { ctx.me = null; updateHeader(); }
  if (location.hash !== '#/signin') {
    try { sessionStorage.setItem(WANTED, location.hash); } catch { /* no storage */ }
    ctx.go('#/signin');
  }
});

document.getElementById('sign-out').addEventListener('click', async () => {
  try { await del('/api/v1/sessions'); } catch { /* signed out either way */ }
  ctx.me = null;
  updateHeader();
  ctx.go('#/signin');
});

// The skip link's "#main" is not a route: it moves focus, not the page.
document.querySelector('a.skip').addEventListener('click', (e) => {
  e.preventDefault();
  (main.querySelector('h1') || main).focus();
});

window.addEventListener('hashchange', route);
document.documentElement.dataset.started = 'yes';  // boot.js: the modules loaded
await loadMe();
route();
