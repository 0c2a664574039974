// A 3D preview of a wall: three.js with OrbitControls, z up as the engine's
// shapes stand (on z = 0 around the z axis). Renders on demand, not in a loop,
// so an idle page costs nothing.
import * as THREE from '/ui/vendor/three/three.module.js';
import { STLLoader } from '/ui/vendor/three/addons/loaders/STLLoader.js';
import { OrbitControls } from '/ui/vendor/three/addons/controls/OrbitControls.js';
import { h } from './dom.js';

const BACKGROUND = 0x20262e;

// A viewer in `box` (an element); label: what the picture shows, for screen readers.
// Answers {show(object), setLabel(text), canvas, dispose()}.
export function createViewer(box, label) {
  // preserveDrawingBuffer: the picture stays readable after it is drawn (a
  // screenshot, the browser test's check that it is not blank).
  const canvas = h('canvas', { class: 'preview', tabindex: '0', role: 'img', 'aria-label': label });
  const wire = h('input', { type: 'checkbox' });
  // See through: a part inside another (a paddle in a tank) hides behind its
  // walls otherwise.
  const xray = h('input', { type: 'checkbox' });
  const reset = h('button', { type: 'button', class: 'secondary small' }, 'Reset view');
  const size = h('span', { class: 'hint preview-size' });
  const tools = h('div', { class: 'preview-tools' },
    h('label', { class: 'check' }, wire, 'Wireframe'),
    h('label', { class: 'check' }, xray, 'See through'), reset, size);
  const hint = h('p', { class: 'hint' },
    'Drag to turn, scroll or pinch to zoom, right-drag to pan; with the picture focused, arrow keys pan.');
  box.replaceChildren(canvas, tools, hint);
  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  } catch {
    box.replaceChildren(h('p', { class: 'alert note' }, 'The 3D preview needs WebGL, which this browser does not offer.'));
    return { show() {}, setLabel() {}, setExtra() {}, dispose() {}, canvas: null };
  }
  renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(BACKGROUND);
  const camera = new THREE.PerspectiveCamera(40, 4 / 3, 0.01, 1e6);
  camera.up.set(0, 0, 1);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x445566, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.4);
  camera.add(sun);  // the light follows the camera, so every side is lit when turned
  sun.position.set(1, 1, 2);
  scene.add(camera);
  const controls = new OrbitControls(camera, canvas);
  controls.listenToKeyEvents(canvas);
  const draw = () => renderer.render(scene, camera);
  controls.addEventListener('change', draw);

  const resize = () => {
    const w = canvas.clientWidth, ht = canvas.clientHeight;
    if (!w || !ht) return;
    renderer.setSize(w, ht, false);
    camera.aspect = w / ht;
    camera.updateProjectionMatrix();
    draw();
  };
  const observer = new ResizeObserver(resize);
  observer.observe(canvas);

  let shown = null;
  let grid = null;
  let extra = null;  // shown with the object, framed by it (particles in a vessel)
  let home = null;  // the camera's first position for the object shown
  function drop(o) {
    if (!o) return;
    scene.remove(o);
    o.traverse((c) => { c.geometry?.dispose(); c.material?.dispose(); });
  }
  function clear() {
    for (const o of [shown, grid, extra]) drop(o);
    shown = grid = extra = null;
  }
  function applyWire() {
    shown?.traverse((o) => {
      if (o.userData.role === 'solid') o.visible = !wire.checked;
      if (o.userData.role === 'edges') o.material.opacity = wire.checked ? 1 : 0.35;
      if (o.userData.role === 'solid') {
        // Without depth writes every surface behind shows through, in any order.
        o.material.transparent = xray.checked;
        o.material.opacity = xray.checked ? 0.35 : 1;
        o.material.depthWrite = !xray.checked;
        o.material.needsUpdate = true;
      }
    });
    draw();
  }
  function goHome() {
    if (!home) return;
    camera.position.copy(home.position);
    controls.target.copy(home.target);
    controls.update();
    draw();
  }
  wire.addEventListener('change', applyWire);
  xray.addEventListener('change', applyWire);
  reset.addEventListener('click', goHome);

  return {
    canvas,
    // Shows a group (from stlObject or draftObject) and frames the camera on it.
    // A draft is seen through when it gets several parts, so a part inside
    // shows, and opaque when it gets one; the box is the user's in between.
    // seeThrough: set the box (what is inside the object matters).
    show(object, { seeThrough } = {}) {
      const parts = object.userData.parts;
      if (parts && parts !== shown?.userData.parts) xray.checked = parts > 1;
      if (seeThrough !== undefined) xray.checked = seeThrough;
      clear();
      shown = object;
      scene.add(object);
      const bounds = new THREE.Box3().setFromObject(object);
      const sphere = bounds.getBoundingSphere(new THREE.Sphere());
      const r = sphere.radius || 1;
      // A floor grid under the object gives the eye its size and which way is up.
      const extent = bounds.getSize(new THREE.Vector3());
      const span = Math.max(extent.x, extent.y) * 1.6 || 1;
      grid = new THREE.GridHelper(span, 10, 0x5c6b7a, 0x3a4654);
      grid.rotateX(Math.PI / 2);
      grid.position.set(sphere.center.x, sphere.center.y, bounds.min.z);
      scene.add(grid);
      size.textContent = `Size ${fmt(extent.x)} × ${fmt(extent.y)} × ${fmt(extent.z)}`;
      const d = r / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 1.05;
      home = {
        target: sphere.center.clone(),
        position: sphere.center.clone().add(new THREE.Vector3(1, -1.4, 0.9).normalize().multiplyScalar(d)),
      };
      camera.near = d / 1000;
      camera.far = d * 100;
      camera.updateProjectionMatrix();
      applyWire();
      goHome();
      resize();
    },
    // Shows `object` (null: none) with the object shown, in its frame, in place of the last one.
    setExtra(object) {
      drop(extra);
      extra = object;
      if (extra) scene.add(extra);
      draw();
    },
    setLabel(text) { canvas.setAttribute('aria-label', text); },
    dispose() {
      observer.disconnect();
      clear();
      controls.dispose();
      renderer.dispose();
      renderer.forceContextLoss();  // browsers allow few live WebGL contexts
    },
  };
}

// Particles as spheres: [[x, y, z, r], ...], one draw for all (an instanced mesh).
export function particlesObject(shown, color = 0xffa64d) {
  const mesh = new THREE.InstancedMesh(new THREE.SphereGeometry(1, 12, 8),
    new THREE.MeshStandardMaterial({ color, roughness: 0.5 }), shown.length);
  const m = new THREE.Matrix4();
  shown.forEach(([x, y, z, r], i) => mesh.setMatrixAt(i, m.makeScale(r, r, r).setPosition(x, y, z)));
  mesh.instanceMatrix.needsUpdate = true;
  mesh.computeBoundingSphere();
  return mesh;
}

// A draft's parts in turn: the builder's Part 1, Part 2, ... (and New job's "What moves").
const PART_COLORS = [0x7fb3e6, 0xe8b060, 0x8fd19e, 0xd98fc4];

function fmt(x) {
  return Number(x.toPrecision(3)).toLocaleString();
}

// A mesh with its triangle edges drawn faintly (or alone, as a wireframe), so
// the division shows. Both sides are drawn: vessels are open.
function meshObject(geometries, color = PART_COLORS[0]) {
  const group = new THREE.Group();
  for (const geometry of [].concat(geometries)) {
    const solid = new THREE.Mesh(geometry, new THREE.MeshPhongMaterial({
      color, flatShading: true, side: THREE.DoubleSide }));
    solid.userData.role = 'solid';
    const edges = new THREE.LineSegments(new THREE.WireframeGeometry(geometry),
      new THREE.LineBasicMaterial({ color: 0xcfe3f7, transparent: true, opacity: 0.35 }));
    edges.userData.role = 'edges';
    group.add(solid, edges);
  }
  return group;
}

// The STL at url (a model's GET /api/v1/models/{id}/stl), as an object to
// show, and its triangle count.
export async function stlObject(url) {
  return stlObjectFromBuffer(await fetchStl(url));
}
// An STL file's bytes, or an Error saying why the server did not give them.
export async function fetchStl(url) {
  const res = await fetch(url, { credentials: 'same-origin' });
  if (!res.ok) {
    let message = `${res.status} ${res.statusText}`;
    try { message = (await res.json()).error || message; } catch { /* not JSON */ }
    throw new Error(message);
  }
  return res.arrayBuffer();
}
export function stlObjectFromBuffer(buffer) {
  const geometry = new STLLoader().parse(buffer);
  const triangles = (geometry.attributes.position?.count || 0) / 3;
  if (!triangles) throw new Error('no triangles in the file');
  geometry.computeBoundingBox();
  const extent = geometry.boundingBox.getSize(new THREE.Vector3());
  return { object: meshObject(geometry), triangles, largestSide: Math.max(extent.x, extent.y, extent.z) };
}

// A lathe (cylinder, cone, funnel) standing on z = 0: the side and the caps
// asked for (caps: both, none, top or bottom), as the engine makes them.
function latheGeometries(r1, r2, ht, segments, caps) {
  const side = new THREE.CylinderGeometry(r2, r1, ht, segments, 1, true)
    .rotateX(Math.PI / 2).translate(0, 0, ht / 2);
  const out = [side];
  if (r1 > 0 && (caps === 'both' || caps === 'bottom')) out.push(new THREE.CircleGeometry(r1, segments));
  if (r2 > 0 && (caps === 'both' || caps === 'top')) out.push(new THREE.CircleGeometry(r2, segments).translate(0, 0, ht));
  return out;
}

// A draft of parametric parts drawn with three's own primitives, before the
// server has built the real mesh (sim/shapes.cpp; defaults copied from there).
// Close in shape; the server's mesh is what the job uses.
export function draftObject(parts) {
  const group = new THREE.Group();
  for (const p of parts) {
    const v = (k, d) => (Number.isFinite(p[k]) ? p[k] : d);
    let geometries;
    switch (p.shape) {
      case 'cylinder':
        geometries = latheGeometries(v('r', 50), v('r', 50), v('h', 100), Math.round(v('segments', 40)), p.caps || 'both');
        break;
      case 'cone':
      case 'funnel': {
        const funnel = p.shape === 'funnel';
        geometries = latheGeometries(v('r1', 10), v('r2', funnel ? 40 : 0), v('h', 30),
          Math.round(v('segments', 64)), p.caps || (funnel ? 'none' : 'both'));
        break;
      }
      case 'box': {
        const z = v('z', 100);
        geometries = [new THREE.BoxGeometry(v('x', 100), v('y', 100), z).translate(0, 0, z / 2)];
        break;
      }
      case 'sphere': {
        const r = v('r', 50);
        // 20 * 4^s triangles on the server; three's detail d gives 20 * (d+1)^2.
        geometries = [new THREE.IcosahedronGeometry(r, 2 ** Math.round(v('subdivisions', 3)) - 1).translate(0, 0, r)];
        break;
      }
      default:
        continue;
    }
    // A lathe along y or x: the engine's turn of its z axis there (sim/shapes.cpp).
    if (p.axis === 'y') for (const g of geometries) g.rotateX(-Math.PI / 2);
    if (p.axis === 'x') for (const g of geometries) g.rotateY(Math.PI / 2);
    for (const g of geometries) g.translate(v('dx', 0), v('dy', 0), v('dz', 0));
    group.add(meshObject(geometries, PART_COLORS[group.children.length % PART_COLORS.length]));
  }
  group.userData.parts = group.children.length;
  return group;
}
