// Browser test of the web UI (web/static/): starts `collidoscope serve` on a
// free port with a fresh data folder, drives Debian's Chromium (headless,
// through playwright-core) through every page, runs axe-core on each, and
// stops the server at the end, pass or fail.
//
//   node tests/web/ui_test.mjs --binary build/app/collidoscope [--root .]
//
// Exits 77 (CTest's SKIP_RETURN_CODE) when Chromium or web/node_modules are
// missing (scripts/install-web.sh installs the latter). Screenshots of every
// page go to $COLLIDO_WEB_SHOTS, else a new folder under the system's temp
// folder; FAILED.png is the page as it was when a step failed.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn, spawnSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { pathToFileURL, fileURLToPath } from 'node:url';

const SKIP = 77;
const TOTAL_LIMIT_MS = 280_000;  // the whole run; CTest's TIMEOUT is above it
const JOB_LIMIT_MS = 120_000;
const STEP_MS = 20_000;          // any single wait in the browser

function arg(name, dflt) {
  const i = process.argv.indexOf(`--${name}`);
  return i > 0 ? process.argv[i + 1] : dflt;
}
const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(arg('root', path.join(here, '..', '..')));
const binary = path.resolve(arg('binary', path.join(root, 'build', 'app', 'collidoscope')));
const chromiumPath = process.env.CHROMIUM || '/usr/bin/chromium';
const modules = path.join(root, 'web', 'node_modules');

for (const [what, p] of [['Chromium', chromiumPath], ['playwright-core (run scripts/install-web.sh)', path.join(modules, 'playwright-core')],
  ['axe-core (run scripts/install-web.sh)', path.join(modules, 'axe-core')],
  ['web/static/vendor (run scripts/install-web.sh)', path.join(root, 'web', 'static', 'vendor')]]) {
  if (!fs.existsSync(p)) {
    console.log(`SKIP: ${what} not found at ${p}`);
    process.exit(SKIP);
  }
}
if (!fs.existsSync(binary)) {
  console.error(`FAIL: no collidoscope binary at ${binary} (build it, or pass --binary)`);
  process.exit(1);
}
const { chromium } = await import(pathToFileURL(path.join(modules, 'playwright-core', 'index.mjs')).href);
const axePath = path.join(modules, 'axe-core', 'axe.min.js');

const shots = process.env.COLLIDO_WEB_SHOTS || fs.mkdtempSync(path.join(os.tmpdir(), 'collido-web-shots-'));
fs.mkdirSync(shots, { recursive: true });
for (const f of fs.readdirSync(shots)) if (f.endsWith('.png')) fs.rmSync(path.join(shots, f));  // this run's only
const dataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'collido-web-data-'));
const ADMIN = { name: 'webadmin', password: 'admin-password-1' };
const USER = { name: 'tester', password: 'tester-password-1' };

let server = null;   // the serve process (its own process group: job-exec children go with it)
let browser = null;
let base = '';
let serverLog = '';

function stopServer() {
  if (server && server.exitCode === null && server.signalCode === null) {
    try { process.kill(-server.pid, 'SIGTERM'); } catch { /* already gone */ }
  }
}
process.on('exit', () => {
  if (server && server.exitCode === null) { try { process.kill(-server.pid, 'SIGKILL'); } catch { /* gone */ } }
  try { fs.rmSync(dataDir, { recursive: true, force: true }); } catch { /* best effort */ }
});
for (const signal of ['SIGINT', 'SIGTERM', 'SIGHUP']) {
  process.on(signal, () => {
    console.error(`stopped by ${signal}`);
    stopServer();
    process.exit(1);
  });
}
// The whole test stops by itself, whatever hangs.
setTimeout(() => {
  console.error(`FAIL: the test ran past ${TOTAL_LIMIT_MS / 1000} s; stopping`);
  stopServer();
  process.exit(1);
}, TOTAL_LIMIT_MS).unref();

before(async () => {
  const made = spawnSync(binary, ['admin', 'create', ADMIN.name, '--data', dataDir], {
    env: { ...process.env, COLLIDO_ADMIN_PASSWORD: ADMIN.password }, encoding: 'utf8', timeout: 30_000 });
  assert.equal(made.status, 0, `admin create failed: ${made.stderr}`);
  server = spawn(binary, ['serve', '--port', '0', '--data', dataDir, '--web', path.join(root, 'web', 'static'),
    // One worker of one thread, and a memory budget the test can go past on purpose.
    '--workers', '1', '--job-threads', '1', '--memory-gb', '4',
    '--cost-model', path.join(root, 'bench', 'data', 'job_model_cpu.json')], { cwd: root, detached: true, stdio: ['ignore', 'pipe', 'pipe'] });
  const port = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`serve printed no address in 20 s:\n${serverLog}`)), 20_000);
    const read = (chunk) => {
      serverLog += chunk;
      const m = serverLog.match(/serving on http:\/\/127\.0\.0\.1:(\d+)/);
      if (m) { clearTimeout(timer); resolve(Number(m[1])); }
    };
    server.stdout.setEncoding('utf8').on('data', read);
    server.stderr.setEncoding('utf8').on('data', read);
    server.on('exit', (code) => { clearTimeout(timer); reject(new Error(`serve exited (${code}):\n${serverLog}`)); });
  });
  base = `http://127.0.0.1:${port}`;
  browser = await chromium.launch({ executablePath: chromiumPath, headless: true, timeout: 30_000,
    // Software WebGL for the three.js previews on machines without a GPU.
    args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader'] });
  console.log(`# server ${base}, data ${dataDir}, screenshots ${shots}`);
});

after(async () => {
  await browser?.close().catch(() => {});
  if (server) {
    const exited = new Promise((r) => server.exitCode !== null ? r() : server.once('exit', r));
    stopServer();
    const killTimer = setTimeout(() => { try { process.kill(-server.pid, 'SIGKILL'); } catch { /* gone */ } }, 5000);
    await exited;
    clearTimeout(killTimer);
  }
  fs.rmSync(dataDir, { recursive: true, force: true });
});


// Serious and critical axe-core violations on the page as it is now.
async function checkA11y(page, name) {
  await page.addScriptTag({ path: axePath });
  const violations = await page.evaluate(async () =>
    (await window.axe.run(document, { resultTypes: ['violations'] })).violations
      .map((v) => ({ id: v.id, impact: v.impact, help: v.help, targets: v.nodes.map((n) => n.target.join(' ')).slice(0, 5) })));
  const bad = violations.filter((v) => v.impact === 'serious' || v.impact === 'critical');
  const minor = violations.filter((v) => !bad.includes(v));
  if (minor.length) console.log(`# axe ${name}: minor: ${minor.map((v) => v.id).join(', ')}`);
  assert.deepEqual(bad, [], `axe on ${name}: ${JSON.stringify(bad, null, 1)}`);
}
const VIEWPORT = { width: 1280, height: 900 };
const PHONE = { width: 390, height: 844 };
async function shot(page, name) {
  await page.evaluate(() => window.scrollTo(0, 0));  // sticky parts sit where they are at the top
  await page.screenshot({ path: path.join(shots, `${name}.png`), fullPage: true });
  // After a full-page capture headless Chromium clamps the scroll position on
  // the next click (the page jumps between mousedown and mouseup, and the click
  // lands elsewhere); resizing the viewport once puts it right.
  const size = page.viewportSize();
  await page.setViewportSize({ ...size, height: size.height + 1 });
  await page.setViewportSize(size);
}

// What a canvas shows: `drawn`, the share of its pixels that are not the
// preview's background (#20262e: the floor grid alone is a few per cent, a
// model far more), and `digest`, a hash of every pixel to tell two pictures apart.
function canvasLook(canvas) {
  return canvas.evaluate((c) => {
    const copy = document.createElement('canvas');
    copy.width = c.width;
    copy.height = c.height;
    const g = copy.getContext('2d');
    g.drawImage(c, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    let drawn = 0, digest = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (Math.abs(d[i] - 0x20) + Math.abs(d[i + 1] - 0x26) + Math.abs(d[i + 2] - 0x2e) > 40) drawn++;
      for (let k = i; k < i + 4; k++) digest = (Math.imul(digest, 31) + d[k]) >>> 0;
    }
    return { drawn: drawn / (c.width * c.height), digest };
  });
}
const drawnShare = async (canvas) => (await canvasLook(canvas)).drawn;
const canvasDigest = async (canvas) => (await canvasLook(canvas)).digest;
// Waits (bounded) until the canvas shows a model: more than `least` of it drawn.
async function waitDrawn(canvas, what, least = 0.06) {
  const until = Date.now() + STEP_MS;
  let share = 0;
  while (Date.now() < until) {
    share = await drawnShare(canvas);
    if (share > least) return share;
    await new Promise((r) => setTimeout(r, 200));
  }
  assert.fail(`${what}: the preview stayed blank (${(share * 100).toFixed(1)} % drawn)`);
}

// No sideways scrolling at this width: the page fits.
async function checkFits(page, name) {
  const [scroll, width] = await page.evaluate(() => [document.documentElement.scrollWidth, document.documentElement.clientWidth]);
  assert.ok(scroll <= width + 1, `${name}: the page is ${scroll} px wide in a ${width} px window`);
}

const TETRAHEDRON = `solid tetra
${[[[0, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 0, 0], [1, 0, 0], [0, 0, 1]], [[0, 0, 0], [0, 0, 1], [0, 1, 0]],
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]]].map((tri) => `facet normal 0 0 0
outer loop
${tri.map((v) => `vertex ${v.join(' ')}`).join('\n')}
endloop
endfacet`).join('\n')}
endsolid tetra
`;

test('web UI', { timeout: TOTAL_LIMIT_MS - 20_000 }, async (t) => {
  // Steps build on each other: after one fails the rest are skipped, not run into timeouts.
  let failed = false;
  let page = null;
  const consoleLines = [];
  const step = (name, fn) => t.test(name, async (st) => {
    if (failed) { st.skip('an earlier step failed'); return; }
    const started = Date.now();
    try { await fn(); } catch (e) {
      failed = true;
      // What the page showed and said, for whoever reads the failure.
      await page?.screenshot({ path: path.join(shots, 'FAILED.png'), fullPage: true }).catch(() => {});
      console.log(`# failed at ${page?.url()}; page console:\n${consoleLines.slice(-20).map((l) => `#   ${l}`).join('\n')}`);
      throw e;
    }
    console.log(`# ${name}: ${((Date.now() - started) / 1000).toFixed(1)} s`);
  });

  // What a browser needs of the server before any page can work.
  await step('the server serves the UI with its content types', async () => {
    for (const [p, want] of [['/', 'text/html'], ['/ui/js/app.js', 'javascript'], ['/ui/css/app.css', 'text/css'],
      ['/ui/vendor/three/three.module.js', 'javascript'], ['/ui/favicon.svg', 'image/svg+xml']]) {
      const res = await fetch(base + p);
      assert.equal(res.status, 200, `GET ${p}`);
      const type = res.headers.get('content-type') || '';
      assert.ok(type.includes(want), `GET ${p} answered Content-Type "${type}", not ${want}: browsers download or refuse it`);
    }
    // The libraries go out gzipped (install-web.sh makes the copies), and unpack whole.
    const lib = await fetch(base + '/ui/vendor/three/three.core.js', { headers: { 'Accept-Encoding': 'gzip' } });
    assert.equal(lib.headers.get('content-encoding'), 'gzip', 'three.js went out as it is, 1.5 MB');
    assert.ok((await lib.text()).length > 1e6, 'three.js unpacked short');
    // The page runs no inline script (a strict Content-Security-Policy can forbid them).
    const html = await (await fetch(base + '/')).text();
    assert.doesNotMatch(html, /<script(?![^>]*\bsrc=)[^>]*>/i, 'index.html has an inline script');
    // The session is a cookie: the pages keep no token.
    const signIn = await fetch(base + '/api/v1/sessions', { method: 'POST', body: JSON.stringify(ADMIN) });
    assert.equal(signIn.status, 200, 'sign in');
    const cookie = signIn.headers.get('set-cookie') || '';
    assert.match(cookie, /collido_session=[^;]+;.*HttpOnly/i, `POST /api/v1/sessions sent no session cookie ("${cookie}")`);
    // A partial answer names its range, or <video> refuses it (videos load with Range: bytes=0-).
    const part = await fetch(base + '/ui/css/app.css', { headers: { Range: 'bytes=0-9' } });
    assert.equal(part.status, 206, 'a Range request answers 206');
    assert.match(part.headers.get('content-range') || '', /^bytes 0-9\/\d+$/, 'a 206 answer without Content-Range');
  });

  const context = await browser.newContext({ viewport: VIEWPORT });
  page = await context.newPage();
  page.setDefaultTimeout(STEP_MS);
  const pageErrors = [];
  page.on('pageerror', (e) => { pageErrors.push(e.message); consoleLines.push(`uncaught: ${e.message}`); });
  page.on('console', (m) => consoleLines.push(`${m.type()}: ${m.text()}`));
  page.on('dialog', (d) => d.accept());  // "Delete …?" confirmations
  t.after(() => context.close().catch(() => {}));
  let jobId = null;
  let shareUrl = null;
  let cupId = null;

  await step('create an account, sign out, sign in by keyboard', async () => {
    await page.goto(base + '/');
    await page.waitForURL(/#\/signin$/);
    await page.getByRole('heading', { name: 'Sign in', level: 1 }).waitFor();
    await checkA11y(page, 'sign in');
    await shot(page, '01-signin');
    // A wrong password shows the API's error.
    await page.fill('#signin-name', 'nobody');
    await page.fill('#signin-password', 'wrong-password');
    await page.click('form:has(#signin-name) button[type=submit]');
    await page.getByRole('alert').filter({ hasText: 'wrong name or password' }).waitFor();
    await shot(page, '02-signin-error');
    await page.fill('#new-name', USER.name);
    await page.fill('#new-password', USER.password);
    await page.click('form:has(#new-name) button[type=submit]');
    await page.waitForURL(/#\/jobs$/);
    await page.getByText(`Signed in as ${USER.name}`).waitFor();
    assert.equal(await page.locator('#nav-admin').isVisible(), false, 'a user sees no Admin link');
    await page.click('#sign-out');
    await page.waitForURL(/#\/signin$/);
    await page.getByRole('heading', { name: 'Sign in', level: 1 }).waitFor();
    // By keyboard only: on a fresh load the first Tab reaches the skip link;
    // the form is typed and sent with Enter.
    await page.reload();
    await page.getByRole('heading', { name: 'Sign in', level: 1 }).waitFor();
    await page.keyboard.press('Tab');
    assert.equal(await page.evaluate(() => document.activeElement?.textContent), 'Skip to content');
    await page.keyboard.press('Enter');  // to the page's heading, staying on the page
    assert.equal(await page.evaluate(() => document.activeElement?.tagName), 'H1');
    assert.match(page.url(), /#\/signin$/);
    await page.focus('#signin-name');
    await page.keyboard.type(USER.name);
    await page.keyboard.press('Tab');
    assert.equal(await page.evaluate(() => document.activeElement?.id), 'signin-password');
    await page.keyboard.type(USER.password);
    await page.keyboard.press('Enter');
    await page.waitForURL(/#\/jobs$/);
    await page.getByRole('heading', { name: 'Jobs', level: 1 }).waitFor();
  });

  await step('models: preview, wireframe, build a cup, upload STL', async () => {
    await page.click('nav >> text=Models');
    await page.getByRole('heading', { name: 'Models', level: 1 }).waitFor();
    await page.getByRole('row', { name: /wall1/ }).waitFor();
    await page.getByRole('button', { name: 'Preview wall1' }).click();
    await page.getByText('wall1: 156 triangles').waitFor();
    await waitDrawn(page.locator('#model-preview canvas'), 'wall1');

    const build = page.getByRole('region', { name: 'Build a vessel' });
    // The name follows the example until one is typed.
    assert.equal(await build.getByLabel('Name').inputValue(), 'my cup');
    await build.getByLabel('Start from').selectOption({ label: 'A ball' });
    assert.equal(await build.getByLabel('Name').inputValue(), 'my ball');
    await build.getByLabel('Start from').selectOption({ label: 'A cup' });
    await build.getByLabel('Name').fill('test cup');
    await build.getByRole('group', { name: 'Part 1' }).getByLabel('Segments').fill('24');
    const draft = build.locator('canvas');
    const solid = await waitDrawn(draft, 'the draft cup');
    // Wireframe: the faces go, the edges stay, so less is drawn; and back.
    await build.getByLabel('Wireframe').check();
    const wire = await drawnShare(draft);
    assert.ok(wire > 0.005 && wire < solid * 0.8, `wireframe drew ${wire}, solid ${solid}`);
    await build.getByLabel('Wireframe').uncheck();
    await build.getByText('cylinder:r=5,h=10,segments=24,caps=bottom').first().waitFor();  // the spec the server gets
    await page.getByRole('button', { name: 'Create model' }).click();
    await page.getByText(/Created “test cup”: \d+ triangles/).waitFor();
    await page.getByRole('row', { name: /test cup/ }).waitFor();
    await page.getByText(/^test cup: \d+ triangles$/).waitFor();  // its server mesh in the preview
    await waitDrawn(page.locator('#model-preview canvas'), 'the server mesh of test cup');
    cupId = (await page.getByRole('link', { name: 'Use in a job: test cup' }).getAttribute('href')).split('=').pop();
    // A union of parts: a funnel over a cup.
    await build.getByLabel('Start from').selectOption({ label: 'A funnel over a cup' });
    await build.getByRole('group', { name: 'Part 2' }).waitFor();
    await build.getByText(/^funnel:r1=2,r2=8,h=8,segments=48,dz=12\+cylinder:r=5,h=10,segments=48,caps=bottom$/).waitFor();
    await waitDrawn(draft, 'the draft funnel and cup');
    await build.getByLabel('Name').fill('hopper');
    await page.getByRole('button', { name: 'Create model' }).click();
    await page.getByText(/Created “hopper”: \d+ triangles/).waitFor();
    await page.getByRole('row', { name: /hopper/ }).waitFor();
    // A drum lies on its side: its axis goes into the spec, and the draft turns with it.
    await build.getByLabel('Start from').selectOption({ label: 'A drum on its side (to turn)' });
    await build.getByText(/^cylinder:r=5,h=4,segments=48,axis=y$/).waitFor();
    await waitDrawn(draft, 'the draft drum');
    assert.equal(await build.getByLabel('See through').isChecked(), false, 'a drum of one part is drawn opaque');
    await build.getByRole('group', { name: 'Part 1' }).getByLabel('Axis').selectOption('x');
    await build.getByText(/^cylinder:r=5,h=4,segments=48,axis=x$/).waitFor();
    await build.getByRole('group', { name: 'Part 1' }).getByLabel('Axis').selectOption('y');
    await build.getByLabel('Name').fill('drum');
    await page.getByRole('button', { name: 'Create model' }).click();
    await page.getByText(/Created “drum”: \d+ triangles/).waitFor();
    // A tank with a paddle: two parts, the second of which a job may turn.
    await build.getByLabel('Start from').selectOption({ label: 'A tank with a paddle (to stir)' });
    await build.getByText(/^cylinder:r=5,h=6,segments=48,caps=bottom\+box:x=7\.5,y=0\.6,z=2,dz=0\.3$/).waitFor();
    await waitDrawn(draft, 'the draft tank');
    // Two parts, the paddle inside the tank: drawn see-through so it shows; the box
    // turns it off and on.
    assert.equal(await build.getByLabel('See through').isChecked(), true, 'a tank and its paddle are seen through');
    await shot(page, '03-models-tank');
    const through = await canvasDigest(draft);
    await build.getByLabel('See through').uncheck();
    assert.notEqual(await canvasDigest(draft), through, 'opaque draws another picture');
    await build.getByLabel('See through').check();
    assert.equal(await canvasDigest(draft), through, 'and see-through the same one again');

    // A file that is not STL: the server's loader says why.
    const upload = page.getByRole('region', { name: 'Upload an STL' });
    await upload.getByLabel('STL file', { exact: true }).setInputFiles({ name: 'broken.stl', mimeType: 'model/stl', buffer: Buffer.from('this is not an STL file') });
    await upload.getByLabel('Name').fill('broken');
    await upload.getByRole('button', { name: 'Upload' }).click();
    await upload.getByRole('alert').filter({ hasText: /The server did not take broken\.stl: .*not ASCII STL/ }).waitFor();
    // A good one: previewed before it is sent, then listed.
    await upload.getByLabel('Name').fill('');
    await upload.getByLabel('STL file', { exact: true }).setInputFiles({ name: 'tetra.stl', mimeType: 'model/stl', buffer: Buffer.from(TETRAHEDRON) });
    await upload.getByText(/^tetra\.stl: \d+ B, 4 triangles\.$/).waitFor();
    await waitDrawn(upload.locator('canvas'), 'the chosen STL file', 0.03);
    assert.equal(await upload.getByLabel('Name').inputValue(), 'tetra');
    await upload.getByRole('button', { name: 'Upload' }).click();
    await upload.getByText('Uploaded “tetra”: 4 triangles.').waitFor();
    await page.getByRole('row', { name: /tetra/ }).waitFor();
    assert.equal(await page.getByRole('row', { name: /broken/ }).count(), 0, 'a refused upload leaves no model behind');
    await checkA11y(page, 'models');
    await shot(page, '03-models');
  });

  await step('new job: live prediction, warnings, submit', async () => {
    // Until one is typed, the radius follows the wall: 1 % of its largest side.
    await page.goto(`${base}/#/new`);
    const wallPick = page.getByLabel('Wall (a model)');
    const radiusField = page.getByLabel('Radius', { exact: true });
    await wallPick.selectOption({ label: (await wallPick.locator('option', { hasText: /^wall2 / }).innerText()) });
    for (let tries = 0; (await radiusField.inputValue()) !== '2'; ++tries) {  // wall2 is 200 tall
      assert.ok(tries < 150, `the radius did not follow wall2: ${await radiusField.inputValue()}`);
      await page.waitForTimeout(100);
    }
    // Until typed, a pour's duration follows the wall: 2 s from wall2's top was a
    // fall that never touched it; the prediction says when the first land.
    const durationField = page.getByLabel('Duration (simulated seconds)');
    for (let tries = 0; Number(await durationField.inputValue()) <= 2; ++tries) {
      assert.ok(tries < 150, `the duration did not follow the pour into wall2: ${await durationField.inputValue()}`);
      await page.waitForTimeout(100);
    }
    await page.locator('#prediction').getByText('Up to date.').waitFor();
    // The method list: the ones a job may step with (the algorithms' "jobs"), auto first.
    const offered = await page.getByLabel('Detection method').locator('option').allTextContents();
    assert.deepEqual(offered, ['auto', 'bin', 'bvh', 'gravity', 'circumcircle', 'midpoint4'], `offered: ${offered}`);
    assert.equal(await page.locator('#prediction').getByText(/nothing would touch the wall/).count(), 0,
      'a fitted duration lets the pour land');
    await shot(page, '04-new-job-fitted-duration');
    // A typed duration stays, and one that ends before the pour lands is said so, as a sentence.
    await durationField.fill('1');
    await page.locator('#prediction').getByText(/^The first particles reach the wall after about .+ nothing would touch the wall; .+\.$/).waitFor();
    assert.equal(await durationField.inputValue(), '1', 'a typed duration stays');
    await radiusField.fill('0.7');
    await wallPick.selectOption({ label: (await wallPick.locator('option', { hasText: /^wall1 / }).innerText()) });
    // Once wall1 is loaded and shown with the particles, the typed radius is still there.
    await page.locator('canvas[aria-label^="3D view of wall1:"]').waitFor();
    assert.equal(await radiusField.inputValue(), '0.7', 'a typed radius stays when the wall changes');
    await page.goto(`${base}/#/models`);
    await page.getByRole('link', { name: 'Use in a job: test cup' }).click();
    await page.getByRole('heading', { name: 'New job', level: 1 }).waitFor();
    assert.equal(await page.getByLabel('Wall (a model)').inputValue(), cupId);
    await page.getByLabel('Count').fill('40');
    await page.getByLabel('Radius', { exact: true }).fill('0.5');
    await page.getByLabel('Duration (simulated seconds)').fill('0.3');
    await page.getByLabel('Frames per second').fill('10');
    await page.getByLabel('Backend').selectOption('cpu');
    await page.getByLabel('Size').selectOption('160x96');
    await page.getByLabel('Also write ParaView files').check();
    // The prediction follows the form: 4 frames, the first and 3 more (0.3 s at 10 frames/s).
    const pred = page.locator('#prediction');
    await pred.getByText('Up to date.').waitFor();
    await pred.locator('dt:text-is("Frames") + dd', { hasText: /^4$/ }).waitFor();
    assert.match(await pred.locator('dt:text-is("Peak memory") + dd').innerText(), /^\d+(\.\d)? (KiB|MiB|GiB)/);
    // The job cost model's time, with its range, and what priced it.
    assert.match(await pred.locator('dt:text-is("Time") + dd').innerText(), /\(likely .+ to .+\)$/);
    assert.match(await pred.locator('dt:text-is("Peak memory") + dd').innerText(), /\(likely .+ to .+\)$/);
    await pred.locator('dt:text-is("Estimated by") + dd', { hasText: 'job cost model' }).waitFor();
    // Where the particles start: the vessel and the pour's places, drawn; a
    // fill starts them through the cup; one that cannot fit says how many do.
    const startCaption = page.locator('#start-preview + p');
    // (0.3 s of a pour at the inlet's rate: most of them are released after the run.)
    await startCaption.getByText(/^40 particles are poured in from the places shown, the last after .+\. The run ends at 300 ms: about \d+ of them never enter it\.$/).waitFor();
    await waitDrawn(page.locator('#start-preview canvas'), 'the cup with the pour');
    const pourLook = await canvasDigest(page.locator('#start-preview canvas'));
    await page.getByLabel('Fill: particles start spread through the vessel').check();
    await startCaption.getByText(/^40 particles start where shown\.$/).waitFor();
    assert.notEqual(await canvasDigest(page.locator('#start-preview canvas')), pourLook,
      'the fill draws its particles elsewhere than the pour');
    await page.getByLabel('Count').fill('20000');
    await startCaption.getByText(/^The particles cannot start: .*holds only \d+ of the 20000 particles/).waitFor();
    await page.getByLabel('Count').fill('40');
    await page.getByLabel('Pour: particles fall in from above the vessel').check();
    await startCaption.getByText(/^40 particles are poured in/).waitFor();
    // One thread per job, where the model was trained on two: said in plain words.
    await pred.getByText(/outside what the predictor was trained on \(.*threads/).waitFor();
    // Too many particles for the server's memory: a plain warning that it would be refused.
    await page.getByLabel('Count').fill('100000000');
    await pred.getByText(/This job would be refused: the run needs about [\d.]+ GiB of memory/).waitFor();
    // ... and the start view follows the form all the same (too many to place for a preview).
    await startCaption.getByText(/^100\D?000\D?000 particles: more than 200000 particles are not placed for a preview/).waitFor();
    await page.getByLabel('Count').fill('40');
    await pred.locator('dt:text-is("Particles") + dd', { hasText: /^40$/ }).waitFor();
    // A mix of sizes: the largest radius must not be below the radius; the job below has one.
    await page.getByLabel('Largest radius').fill('0.3');
    await pred.getByText(/Largest radius: at least the radius/).waitFor();
    await page.getByLabel('Largest radius').fill('0.6');
    await pred.getByText('Up to date.').waitFor();
    // A pour rate beyond what the inlet can deliver is refused with the reason.
    await page.getByLabel('Pour rate (particles a second)').fill('1e9');
    await pred.getByText(/Check the form: .*rate/).waitFor();
    await page.getByLabel('Pour rate (particles a second)').fill('');
    await pred.getByText('Up to date.').waitFor();
    // A value out of range is named before anything is sent.
    await page.getByLabel('Restitution').fill('7');
    await pred.getByText(/Restitution:/).waitFor();
    await page.getByLabel('Restitution').fill('0.4');
    await pred.getByText('Up to date.').waitFor();
    await pred.locator('dt:text-is("Particles") + dd', { hasText: /^40$/ }).waitFor();
    // A turning wall: its fields appear with it, and the prediction says the
    // model never saw one; a shake asks for its own. The job below turns slowly
    // (6 a minute about y: 11 degrees in its 0.3 s) with the linear law.
    const turns = page.getByLabel('Turns a minute');
    assert.equal(await turns.isVisible(), false, 'no turn rate for a wall that stands still');
    await page.getByLabel('The wall', { exact: true }).selectOption('rotate');
    await turns.fill('12');
    await page.getByLabel('Contact law').selectOption('hertz_mindlin');
    await pred.getByText(/the wall moves \(rotate\): every training job's wall stood still/).waitFor();
    await pred.getByText(/contact model hertz_mindlin/).waitFor();
    // A wall of several parts: one of them may move (the hopper's cup turning under its funnel).
    const whatMoves = page.getByLabel('What moves');
    assert.equal(await whatMoves.isVisible(), false, 'the test cup is one part');
    const hopper = await page.locator('option', { hasText: 'hopper' }).getAttribute('value');
    await page.getByLabel('Wall (a model)').selectOption(hopper);
    await whatMoves.selectOption({ label: 'Part 2: cylinder' });
    await pred.getByText('Up to date.').waitFor();
    await pred.getByText(/the wall moves \(rotate\)/).waitFor();
    await shot(page, '04-new-job-turning-part');
    await page.getByLabel('Wall (a model)').selectOption(cupId);
    await pred.getByText('Up to date.').waitFor();
    assert.equal(await whatMoves.isVisible(), false);
    await page.getByLabel('The wall', { exact: true }).selectOption('oscillate');
    assert.equal(await turns.isVisible(), false);
    await page.getByLabel('Amplitude').fill('0.2');
    await pred.getByText(/the wall moves \(oscillate\)/).waitFor();
    await checkA11y(page, 'new job, a moving wall');
    await page.getByLabel('The wall', { exact: true }).selectOption('none');
    await page.getByLabel('Contact law').selectOption('linear');
    await pred.getByText('Up to date.').waitFor();
    assert.equal(await pred.getByText(/the wall moves/).count(), 0);
    await page.getByLabel('The wall', { exact: true }).selectOption('rotate');
    await turns.fill('6');
    await pred.getByText(/the wall moves \(rotate\)/).waitFor();
    await checkA11y(page, 'new job');
    await shot(page, '04-new-job');
    await page.getByRole('button', { name: 'Submit job' }).click();
    await page.waitForURL(/#\/jobs\/[A-Za-z0-9_-]+$/);
    jobId = page.url().split('/').pop();
  });

  await step('result: the job finishes, video seeks, chart, downloads', async () => {
    await page.locator('.state-done, .state-failed, .state-cancelled').first().waitFor({ timeout: JOB_LIMIT_MS });
    const failure = await page.locator('.alert.error').allInnerTexts();
    assert.equal(await page.locator('.state-done').count(), 1, `the job did not finish: ${failure.join(' ')}`);
    await page.getByRole('heading', { name: 'test cup: 40 particles', level: 1 }).waitFor();
    await page.locator('dt:text-is("Wall motion") + dd', { hasText: 'turns 6 a minute about y' }).waitFor();
    await page.locator('dt:text-is("Particles") + dd', { hasText: '40, radius 0.5 to 0.6' }).waitFor();
    const video = page.locator('video');
    await video.waitFor();
    assert.equal(await video.locator('source[type="video/webm"]').count(), 1);
    assert.equal(await video.locator('source[type="video/mp4"]').count(), 1);
    // A source loads: the element has picked one and read its metadata; then it seeks.
    const loaded = await page.waitForFunction(() => {
      const v = document.querySelector('video');
      if (v.error) return { error: v.error.code };
      return v.readyState >= 1 && v.currentSrc ? { src: v.currentSrc, duration: v.duration } : false;
    }, null, { timeout: STEP_MS }).then((h) => h.jsonValue());
    assert.ok(!loaded.error, `the video did not load (MediaError ${loaded.error})`);
    assert.ok(loaded.duration > 0, `video duration ${loaded.duration}`);
    const seeked = await page.evaluate((limit) => new Promise((resolve) => {
      const v = document.querySelector('video');
      const target = v.duration / 2;
      const timer = setTimeout(() => resolve({ timeout: true, at: v.currentTime }), limit);
      v.addEventListener('seeked', () => { clearTimeout(timer); resolve({ at: v.currentTime, target }); }, { once: true });
      v.currentTime = target;
    }), STEP_MS);
    assert.ok(!seeked.timeout, `the video did not seek (at ${seeked.at})`);
    assert.ok(Math.abs(seeked.at - seeked.target) < 0.2, `seeked to ${seeked.at}, not ${seeked.target}`);

    await page.getByRole('heading', { name: 'Key figures' }).waitFor();
    await page.locator('dl.figures dt:text-is("Particles") + dd', { hasText: '40' }).waitFor();
    assert.equal(await page.locator('.uplot canvas').count() >= 3, true, 'contacts, energy and one more chart');
    await page.getByText('Contacts over 4 frames').waitFor();
    await page.getByText(/^Energy \(J\) over 4 frames/).waitFor();
    for (const name of ['MP4 video', 'WebM video', 'Animated GIF', 'Poster image (PNG)', 'Statistics per frame (CSV)', 'frames.pvd']) {
      await page.getByRole('link', { name, exact: true }).waitFor();
    }
    // The downloads are real files.
    const gif = await page.evaluate(async (href) => (await fetch(href)).headers.get('content-type'),
      await page.getByRole('link', { name: 'Animated GIF' }).getAttribute('href'));
    assert.equal(gif, 'image/gif');
    await page.getByText('The .vtp files').click();
    await page.getByRole('link', { name: 'frame_000003.vtp' }).waitFor();
    await page.getByText('Predicted', { exact: true }).waitFor();
    // Predicted and measured frames are counted alike (the first one too).
    const framesCells = await page.locator('tr:has(th:text-is("Frames")) td').allInnerTexts();
    assert.deepEqual(framesCells.slice(0, 2), ['4', '4'], `frames predicted and measured: ${framesCells}`);
    await checkA11y(page, 'result');
  });

  await step('share: the link works without an account, and not after revoking', async () => {
    await page.getByRole('button', { name: 'Make a share link' }).click();
    shareUrl = await page.getByLabel('Share link').inputValue();
    assert.match(shareUrl, /\/s\/[A-Za-z0-9_-]+$/);
    const embedCode = await page.getByLabel('Embed in a page or slides').inputValue();
    assert.match(embedCode, /^<iframe src="[^"]+\/embed\/[A-Za-z0-9_-]+" [^>]*title="[^"]+"[^>]*><\/iframe>$/);
    await page.getByRole('status').filter({ hasText: /Link (copied|selected)/ }).waitFor();
    await shot(page, '05-result');
    const local = (u) => u.replace(/^https?:\/\/[^/]+/, base);

    // A visitor: a fresh browser context, no cookie.
    const visitor = await browser.newContext({ viewport: VIEWPORT });
    try {
      const v = await visitor.newPage();
      v.setDefaultTimeout(STEP_MS);
      const res = await v.goto(local(shareUrl));
      assert.equal(res.status(), 200, 'the share link opens without an account');
      await v.waitForFunction(() => {
        const el = document.querySelector('video');
        return el && el.readyState >= 1 && el.duration > 0;
      });
      await v.screenshot({ path: path.join(shots, '08-shared.png'), fullPage: true });
      const embedUrl = embedCode.match(/src="([^"]+)"/)[1];
      const embedRes = await v.goto(local(embedUrl));
      assert.equal(embedRes.status(), 200, 'the embed page opens without an account');
      await v.locator('video').waitFor();

      await page.getByRole('button', { name: 'Revoke link' }).click();
      await page.getByText('The link was revoked').waitFor();
      const gone = await v.goto(local(shareUrl));
      assert.equal(gone.status(), 404, 'a revoked link answers 404');
      await v.getByText(/not found|does not exist/i).first().waitFor();
      await v.screenshot({ path: path.join(shots, '09-shared-revoked.png'), fullPage: true });
    } finally {
      await visitor.close().catch(() => {});
    }
    // Sharing again works after a revoke, and a link made on one visit is
    // listed on the next, to copy or revoke there.
    await page.getByRole('button', { name: 'Make a share link' }).click();
    const again = await page.getByLabel('Share link').inputValue();
    assert.notEqual(again, shareUrl);
    await page.reload();
    await page.getByRole('heading', { name: 'Share' }).waitFor();
    await page.getByRole('button', { name: 'Make another share link' }).waitFor();
    assert.equal(await page.getByLabel('Share link').inputValue(), again, 'the link is listed on a later visit');
    await page.getByRole('button', { name: 'Revoke link' }).click();
    await page.getByText('The link was revoked').waitFor();
    await page.getByRole('button', { name: 'Make a share link' }).waitFor();
    assert.equal(await page.getByLabel('Share link').count(), 0);
  });

  await step('a link to a job, opened signed out, leads there after signing in', async () => {
    await page.click('#sign-out');
    await page.waitForURL(/#\/signin$/);
    await page.goto(`${base}/#/jobs/${jobId}`);
    await page.waitForURL(/#\/signin$/);
    await page.fill('#signin-name', USER.name);
    await page.fill('#signin-password', USER.password);
    await page.click('form:has(#signin-name) button[type=submit]');
    await page.waitForURL(new RegExp(`#/jobs/${jobId}$`));
    await page.getByRole('heading', { name: 'test cup: 40 particles', level: 1 }).waitFor();
  });

  await step('jobs: live progress, would-wait warning, cancel and delete', async () => {
    // A long job, sent with the page's own session, to watch and cancel.
    const long = await page.evaluate(async (wall) => {
      const res = await fetch('/api/v1/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' },
        body: JSON.stringify({ scene: { wall: { model: Number(wall) }, particles: { count: 3000, radius: 0.3 }, placement: { kind: 'pour' },
          duration: 30, fps: 24 }, render: { width: 160, height: 96 } }) });
      return { status: res.status, body: await res.json() };
    }, cupId);
    assert.equal(long.status, 202, JSON.stringify(long.body));
    await page.click('nav >> text=Jobs');
    await page.getByRole('heading', { name: 'Jobs', level: 1 }).waitFor();
    const row = page.getByRole('row', { name: new RegExp(long.body.id) });
    await row.getByText('running').waitFor();
    await row.locator('progress').waitFor();
    const doneRow = page.getByRole('row', { name: new RegExp(jobId) });
    await doneRow.getByText('done').waitFor();
    assert.equal(await doneRow.locator('td').nth(1).innerText(), 'test cup');
    await checkA11y(page, 'jobs');
    await shot(page, '06-jobs');

    // While it runs, a new job would wait: the prediction says so.
    await page.click('nav >> text=New job');
    await page.locator('#prediction').getByText(/would wait its turn/).waitFor();

    await page.click('nav >> text=Jobs');
    // Polling updates the progress in place: a button the keyboard is on
    // keeps the focus across polls (it was replaced every 1.5 s).
    const cancel = row.getByRole('button', { name: /^Cancel job/ });
    await cancel.focus();
    const progressBefore = await row.locator('progress').getAttribute('value');
    await page.waitForFunction(([id, before]) => {
      const tr = [...document.querySelectorAll('tr')].find((r) => r.textContent.includes(id));
      return tr && tr.querySelector('progress')?.getAttribute('value') !== before;
    }, [long.body.id, progressBefore]);
    assert.ok(await cancel.evaluate((el) => el === document.activeElement), 'the focused button kept the focus across a poll');
    await cancel.click();
    await row.getByText('cancelled').waitFor();
    await row.getByRole('button', { name: /^Delete job/ }).click();
    await row.waitFor({ state: 'detached' });
    await doneRow.waitFor();
  });

  await step('jobs: the newest 50, older ones behind a button', async () => {
    // 50 more jobs: one tiny scene run once, then submitted again (reused at once).
    const made = await page.evaluate(async () => {
      const body = JSON.stringify({ scene: { wall: 'wall1', particles: { count: 40, radius: 0.5 }, placement: { kind: 'pour' },
        duration: 0.3, fps: 10 }, render: { width: 160, height: 96, formats: ['gif'] } });
      const post = async () => {
        const r = await fetch('/api/v1/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body });
        return { status: r.status, body: await r.json() };
      };
      const first = await post();
      if (first.status !== 202) return { error: JSON.stringify(first) };
      for (let t = 0; ; ++t) {
        const j = await (await fetch(`/api/v1/jobs/${first.body.id}`)).json();
        if (j.state === 'done') break;
        if (j.state !== 'queued' && j.state !== 'running') return { error: JSON.stringify(j) };
        if (t > 1200) return { error: 'the tiny job did not finish in 2 minutes' };
        await new Promise((ok) => setTimeout(ok, 100));
      }
      const statuses = [];
      for (let k = 0; k < 49; ++k) statuses.push((await post()).status);
      const total = (await (await fetch('/api/v1/jobs?limit=1000')).json()).length;
      return { statuses, total };
    });
    assert.ok(!made.error, made.error);
    assert.ok(made.statuses.every((st) => st === 200), `resubmissions answered ${made.statuses}`);
    assert.ok(made.total > 50, `${made.total} jobs`);
    await page.reload();  // the list on screen stopped polling when its jobs ended
    await page.getByRole('heading', { name: 'Jobs', level: 1 }).waitFor();
    const rows = page.locator('table tbody tr');
    const older = page.getByRole('button', { name: 'Show older jobs' });
    await older.waitFor();
    assert.equal(await rows.count(), 50);
    await shot(page, '06-jobs-older');
    await older.click();
    await page.waitForFunction((n) => document.querySelectorAll('table tbody tr').length === n, made.total);
    assert.ok(await older.isHidden(), 'the button stays after the last page');
    assert.ok(await page.evaluate(() => document.activeElement?.closest('tr') ===
      document.querySelectorAll('table tbody tr')[50]), 'the focus went to the first job the last page showed');
    await checkA11y(page, 'jobs, two pages');
  });

  await step('phone width: every page fits', async () => {
    await page.setViewportSize(PHONE);
    for (const [hash, heading, name] of [['#/jobs/' + jobId, 'test cup: 40 particles', '10-phone-result'],
      ['#/new', 'New job', '11-phone-new-job'], ['#/models', 'Models', '12-phone-models'], ['#/jobs', 'Jobs', null], ['#/methods', 'Methods', '14-phone-methods']]) {
      await page.goto(`${base}/${hash}`);
      await page.getByRole('heading', { name: heading, level: 1 }).waitFor();
      await page.waitForLoadState('networkidle');
      await checkFits(page, hash);
      // On a phone the prediction is below the form; a line at the foot of the screen follows it.
      if (hash === '#/new') await page.locator('.pred-mini', { hasText: /^Prediction: .+ \(likely .+\), [\d.]+ [KMG]iB .*of memory/ }).waitFor();
      if (name) await shot(page, name);
    }
    await page.setViewportSize(VIEWPORT);
  });

  await step('methods page', async () => {
    await page.click('nav >> text=Methods');
    await page.getByRole('heading', { name: 'Methods', level: 1 }).waitFor();
    await page.getByRole('row', { name: /midpoint4/ }).waitFor();
    // The octree is described, and said to be for detection frames, not jobs.
    assert.match(await page.getByRole('row', { name: /^octree / }).innerText(), /Jobs cannot choose it yet/);
    // The study's charts (installed from docs/img/study/): a Pareto chart that loads, and the paper's Table 4.
    await page.getByRole('heading', { name: 'Full study, NVIDIA H200' }).waitFor();
    const pareto = page.locator('img[src*="/ui/study/gpu/pareto_"]').first();
    await pareto.waitFor();
    await page.waitForFunction((el) => el.complete && el.naturalWidth > 0, await pareto.elementHandle());
    await page.locator('img[src="/ui/study/gpu/paper_table4.png"]').waitFor();
    await page.getByText(/method auto picked (bin|bvh)\/particle.*on the Pareto front/).first().waitFor();
    await checkA11y(page, 'methods');
    await shot(page, '13-methods');
  });

  await step('admin: the run log and the algorithms, for administrators only', async () => {
    await page.goto(base + '/#/admin');
    await page.getByRole('heading', { name: 'Administrators only' }).waitFor();
    await page.click('#sign-out');
    await page.waitForURL(/#\/signin$/);
    await page.fill('#signin-name', ADMIN.name);
    await page.fill('#signin-password', ADMIN.password);
    await page.click('form:has(#signin-name) button[type=submit]');
    await page.waitForURL(/#\/jobs$/);
    await page.click('#nav-admin a');
    await page.getByRole('heading', { name: 'Administration', level: 1 }).waitFor();
    const logRow = page.getByRole('row', { name: new RegExp(jobId.slice(0, 8)) });
    await logRow.waitFor();
    assert.doesNotMatch(await logRow.innerText(), /not predicted/);
    const predictor = page.getByRole('region', { name: 'Cost predictor' });
    await predictor.getByRole('heading', { name: /job_model_cpu\.json: cpu jobs/ }).waitFor();
    await predictor.getByText(/Predicted at submission against measured.*total time off by/).waitFor();
    // The loss curve and the held-out predictions, drawn.
    await predictor.locator('canvas').nth(1).waitFor();
    assert.equal(await predictor.locator('canvas').count(), 2);
    // Retraining on demand: one service job is too few to compare on, and the page says so.
    await predictor.getByText(/Not retrained since the server started/).waitFor();
    await predictor.getByRole('button', { name: 'Retrain now' }).click();
    await predictor.getByText(/cpu: too few/).waitFor({ timeout: 120000 });
    await page.getByRole('region', { name: 'Algorithms' }).getByRole('row', { name: /gravity/ }).waitFor();
    await checkA11y(page, 'admin');
    await shot(page, '07-admin');
  });

  assert.deepEqual(pageErrors, [], 'uncaught errors in the page');
});
