// imubake view: the take's character in 3D (three.js, its glTF loader and animation mixer).
//
// The server gives /take.json (fps as num/den, frames, chunk length, joints in rig order, the
// sensors' mounts, the feet, the contacts) and the motion as GLB chunks keyed at the take's own
// times n·den/num. The page shows whole frames: frame n is chunk min(⌊n / F⌋, chunks − 1) at its
// key n − k·F. A live session sends poses over /live instead.
//
// Units and axes are glTF's: metres, Y up. Quaternions arrive [w, x, y, z]; three.js takes x y z w.
//
// `#frame=N` opens the page paused at frame N (and `follow=0` keeps the camera still); the hash
// follows the shown frame while paused, so the address bar links to the moment.
// `window.imubake` is a hook for tests and scripts: see the end of this file.

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const $ = (id) => document.getElementById(id);

const hook = {
  ready: false,
  frame: -1,
  time_s: NaN,
  live_frame: -1,
  errors: [],
  bones: () => [],
  screen: () => [],
  show: async () => {},
};
window.imubake = hook;

function fail(message) {
  hook.errors.push(String(message));
  const box = $('error');
  box.textContent = String(message);
  box.hidden = false;
}

function params() {
  const out = {};
  for (const part of location.hash.replace(/^#/, '').split('&')) {
    const [k, v] = part.split('=');
    if (k) out[decodeURIComponent(k)] = decodeURIComponent(v ?? '');
  }
  return out;
}

// Frame n's time, from the rational rate (never accumulated).
const frameTime = (take, n) => (n * take.fps.den) / take.fps.num;

function formatTime(s) {
  const m = Math.floor(s / 60);
  const rest = s - m * 60;
  return m > 0 ? `${m}:${rest.toFixed(3).padStart(6, '0')}` : `${rest.toFixed(3)} s`;
}

async function main() {
  const response = await fetch('/take.json');
  if (!response.ok) throw new Error(`/take.json: ${response.status}`);
  const take = await response.json();
  document.title = `${take.name} · imubake view`;
  $('name').textContent = take.name;
  $('source').textContent = take.live
    ? 'live'
    : `${take.source} · ${take.frames} frames at ${take.fps.num}/${take.fps.den} fps`;

  // Renderer, scene, light, floor.
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio);
  renderer.setSize(window.innerWidth, window.innerHeight);
  $('view').appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x1d2127);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404850, 2.2));
  const sun = new THREE.DirectionalLight(0xffffff, 1.6);
  sun.position.set(3, 6, 4);
  scene.add(sun);
  scene.add(floorGrid(40));
  const camera = new THREE.PerspectiveCamera(40, window.innerWidth / window.innerHeight, 0.05, 500);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.enableDamping = false;

  // Chunks: a promise each, loaded on demand, a few kept.
  const loader = new GLTFLoader();
  const chunks = new Map();
  function chunk(k) {
    if (!chunks.has(k)) {
      chunks.set(k, loader.loadAsync(`/chunk/${k}.glb`).then((gltf) => ({ k, gltf })));
      while (chunks.size > 4) chunks.delete(chunks.keys().next().value);
    }
    return chunks.get(k);
  }

  const first = await chunk(0);
  const character = first.gltf.scene;
  scene.add(character);
  let skinned = null;
  character.traverse((o) => {
    if (o.isSkinnedMesh && !skinned) skinned = o;
    if (o.isMesh) o.frustumCulled = false;
  });
  if (!skinned) throw new Error('the take has no skinned mesh');
  const bones = skinned.skeleton.bones; // rig order: skin joint i is joint i
  const boneNamed = new Map(take.joints.map((name, i) => [name, bones[i]]));
  const mixer = new THREE.AnimationMixer(character);

  // Sensors' axes: each on its bone, turned by its mount q_bone_sensor.
  const sensorAxes = [];
  for (const s of take.sensors) {
    const bone = boneNamed.get(s.bone);
    if (!bone) continue;
    const axes = new THREE.AxesHelper(0.15);
    const [w, x, y, z] = s.mount;
    axes.quaternion.set(x, y, z, w);
    axes.visible = false;
    axes.name = `sensor ${s.sensor}`;
    axes.userData = { sensor: s.sensor, bone: s.bone };
    bone.add(axes);
    sensorAxes.push(axes);
  }
  // One switch for all, and one per sensor (listed under it).
  $('show-sensors').disabled = sensorAxes.length === 0;
  const list = $('sensor-list');
  const boxes = sensorAxes.map((axes) => {
    const label = document.createElement('label');
    const box = document.createElement('input');
    box.type = 'checkbox';
    box.addEventListener('change', () => { axes.visible = box.checked; });
    label.append(box, ` ${axes.userData.sensor} → ${axes.userData.bone}`);
    list.appendChild(label);
    return box;
  });
  $('show-sensors').addEventListener('change', (e) => {
    sensorAxes.forEach((a, i) => { a.visible = e.target.checked; boxes[i].checked = e.target.checked; });
    list.hidden = !e.target.checked;
  });

  // Foot contacts: a disc under each planted foot, and the timeline's strip.
  const feet = (take.feet ?? []).map((name) => boneNamed.get(name));
  const contactDiscs = feet.map((_, side) => {
    const disc = new THREE.Mesh(
      new THREE.CircleGeometry(0.09, 32).rotateX(-Math.PI / 2),
      new THREE.MeshBasicMaterial({ color: side === 0 ? 0x4fc3f7 : 0xffb74d }),
    );
    disc.visible = false;
    scene.add(disc);
    return disc;
  });
  const planted = (side, n) => {
    const runs = take.contacts ? (side === 0 ? take.contacts.left : take.contacts.right) : [];
    return runs.some(([s, e]) => n >= s && n <= e);
  };
  $('show-contacts').disabled = !take.contacts;
  drawContactStrip(take);

  // The frame shown: chunk k's clip at its key n − k·F.
  let action = null;
  let actionChunk = -1;
  let shown = -1;
  const world = new THREE.Vector3();
  function place(n) {
    const show = $('show-contacts').checked && take.contacts;
    feet.forEach((bone, side) => {
      const disc = contactDiscs[side];
      disc.visible = Boolean(show && bone && planted(side, n));
      if (disc.visible) {
        bone.getWorldPosition(world);
        disc.position.set(world.x, 0.002, world.z);
      }
    });
  }
  async function show(n) {
    n = Math.max(0, Math.min(take.frames - 1, Math.round(n)));
    const k = Math.min(Math.floor(n / take.chunk_frames), take.chunks - 1);
    const c = await chunk(k);
    if (actionChunk !== k) {
      const clip = c.gltf.animations[0];
      if (action) action.stop();
      action = mixer.clipAction(clip);
      action.setLoop(THREE.LoopOnce, 1);
      action.clampWhenFinished = true;
      action.play();
      actionChunk = k;
    }
    const times = action.getClip().tracks[0].times;
    const key = Math.min(n - k * take.chunk_frames, times.length - 1);
    action.enabled = true;
    action.paused = false;
    action.time = times[key];
    mixer.update(0);
    character.updateMatrixWorld(true);
    shown = n;
    hook.frame = n;
    hook.time_s = frameTime(take, n);
    $('scrub').value = String(n);
    $('counter').textContent = `frame ${n} / ${take.frames - 1}`;
    $('time').textContent = formatTime(hook.time_s);
    place(n);
    // The next chunk, before the scrubber gets there.
    if (k + 1 < take.chunks && n - k * take.chunk_frames > take.chunk_frames / 2) chunk(k + 1);
    return n;
  }

  // Camera: in front of the body (rig +Z is its front), looking at the hips.
  const hips = bones[0];
  const target = new THREE.Vector3();
  function frameCamera() {
    character.updateMatrixWorld(true);
    hips.getWorldPosition(target);
    const box = new THREE.Box3().setFromObject(skinned, true);
    const height = Math.max(box.max.y - box.min.y, 0.5);
    target.y = box.min.y + height * 0.5;
    controls.target.copy(target);
    // Closer when following; a still camera stands back to keep more of the path in view.
    const away = follow ? 2.2 : 3.4;
    camera.position.set(target.x + height * away * 0.35, target.y + height * 0.45, target.z + height * away);
    controls.update();
  }
  let follow = params().follow !== '0';
  $('follow').checked = follow;
  $('follow').addEventListener('change', (e) => { follow = e.target.checked; });
  const last = new THREE.Vector3();
  function followHips() {
    hips.getWorldPosition(world);
    if (follow) {
      const dx = world.x - last.x;
      const dz = world.z - last.z;
      camera.position.x += dx; camera.position.z += dz;
      controls.target.x += dx; controls.target.z += dz;
    }
    last.copy(world);
  }

  // Playback: whole frames at the take's rate times the speed.
  let playing = false;
  let playStart = 0;
  let playFrom = 0;
  const speed = () => Number($('speed').value);
  function setPlaying(on) {
    playing = on && !take.live;
    $('play').innerHTML = playing ? '&#10074;&#10074;' : '&#9654;';
    $('play').setAttribute('aria-label', playing ? 'pause' : 'play');
    playFrom = shown >= take.frames - 1 ? 0 : shown;
    playStart = performance.now();
    if (!playing) history.replaceState(null, '', `#frame=${shown}${follow ? '' : '&follow=0'}`);
  }
  $('play').addEventListener('click', () => setPlaying(!playing));
  $('speed').addEventListener('change', () => setPlaying(playing));
  window.addEventListener('keydown', (e) => {
    if (e.code === 'Space') { e.preventDefault(); setPlaying(!playing); }
    if (e.code === 'ArrowRight') { setPlaying(false); show(shown + 1).then(() => setPlaying(false)); }
    if (e.code === 'ArrowLeft') { setPlaying(false); show(shown - 1).then(() => setPlaying(false)); }
  });
  $('scrub').max = String(take.frames - 1);
  $('scrub').addEventListener('input', (e) => {
    playing = false;
    show(Number(e.target.value)).then(() => setPlaying(false));
  });
  window.addEventListener('hashchange', () => {
    const p = params();
    if (p.frame !== undefined) { playing = false; show(Number(p.frame)).then(() => setPlaying(false)); }
  });

  let busy = false;
  function tick() {
    requestAnimationFrame(tick);
    if (playing && !busy) {
      const elapsed = ((performance.now() - playStart) / 1000) * speed();
      const n = playFrom + Math.floor((elapsed * take.fps.num) / take.fps.den + 1e-9);
      if (n >= take.frames) {
        busy = true;
        show(take.frames - 1).then(() => { busy = false; setPlaying(false); });
      } else if (n !== shown) {
        busy = true;
        show(n).then(() => { busy = false; });
      }
    }
    followHips();
    renderer.render(scene, camera);
  }

  window.addEventListener('resize', () => {
    camera.aspect = window.innerWidth / window.innerHeight;
    camera.updateProjectionMatrix();
    renderer.setSize(window.innerWidth, window.innerHeight);
    drawContactStrip(take);
  });

  // The test hook: world positions (metres) and screen positions (CSS pixels) of the joints.
  hook.bones = () => bones.map((b) => b.getWorldPosition(new THREE.Vector3()).toArray());
  hook.screen = () => {
    camera.updateMatrixWorld(true);
    return bones.map((b) => {
      const v = b.getWorldPosition(new THREE.Vector3()).project(camera);
      return [((v.x + 1) / 2) * window.innerWidth, ((1 - v.y) / 2) * window.innerHeight];
    });
  };
  hook.joints = take.joints;
  hook.show = async (n) => { playing = false; const m = await show(n); setPlaying(false); renderer.render(scene, camera); return m; };

  if (take.live) {
    $('controls').hidden = true;
    $('live-status').hidden = false;
    $('live-status').textContent = 'connecting…';
    await show(0);
    frameCamera();
    mixer.stopAllAction();
    startLive(take, bones, (n) => { place(n); hook.live_frame = n; });
  } else {
    const start = Number(params().frame ?? 0);
    await show(Number.isFinite(start) ? start : 0);
    frameCamera();
    setPlaying(false);
  }
  hips.getWorldPosition(last);
  renderer.render(scene, camera);
  hook.ready = true;
  tick();
}

// The floor: 1 m squares over size × size metres, the axes through the origin brighter. Each
// line is cut into 1 m segments, so a line passing under the camera is still drawn by renderers
// that drop a segment crossing the near plane (SwiftShader does).
function floorGrid(size) {
  const half = size / 2;
  const points = [];
  const colors = [];
  const major = new THREE.Color(0x6a7280);
  const minor = new THREE.Color(0x3a414c);
  for (let k = -half; k <= half; k++) {
    const c = k === 0 ? major : minor;
    for (let s = -half; s < half; s++) {
      points.push(s, 0, k, s + 1, 0, k, k, 0, s, k, 0, s + 1);
      for (let v = 0; v < 4; v++) colors.push(c.r, c.g, c.b);
    }
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(points, 3));
  geometry.setAttribute('color', new THREE.Float32BufferAttribute(colors, 3));
  return new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ vertexColors: true }));
}

// The contacts under the scrubber: left foot above, right below, airborne stretches dim.
function drawContactStrip(take) {
  const canvas = $('contacts');
  if (!take.contacts || take.frames < 2) { canvas.hidden = true; return; }
  const width = canvas.clientWidth || 600;
  canvas.width = width;
  const g = canvas.getContext('2d');
  g.clearRect(0, 0, width, 10);
  const x = (n) => (n / (take.frames - 1)) * width;
  const bar = (runs, y, h, color) => {
    g.fillStyle = color;
    for (const [s, e] of runs) g.fillRect(x(s), y, Math.max(1, x(e + 1) - x(s)), h);
  };
  bar(take.contacts.airborne ?? [], 0, 10, 'rgba(255,255,255,0.12)');
  bar(take.contacts.left, 0, 4, '#4fc3f7');
  bar(take.contacts.right, 6, 4, '#ffb74d');
}

// A live session: each pose message sets the joints directly; the status fills the panel.
function startLive(take, bones, placed) {
  const status = $('live-status');
  const socket = new WebSocket(`ws://${location.host}/live`);
  socket.onmessage = (event) => {
    const m = JSON.parse(event.data);
    if (m.type === 'pose') {
      m.rotations.forEach(([w, x, y, z], i) => { if (bones[i]) bones[i].quaternion.set(x, y, z, w); });
      bones[0].position.fromArray(m.root);
      bones[0].updateMatrixWorld(true);
      hook.frame = m.frame;
      hook.time_s = m.time_s;
      placed(m.frame);
    } else if (m.type === 'status') {
      const phase = m.phase === 'calibrating'
        ? `hold the pose: ${(m.calibrating_left_s ?? 0).toFixed(1)} s`
        : m.phase === 'running' ? `${m.frames} frames` : 'waiting for data';
      status.replaceChildren(document.createTextNode(phase));
      for (const s of m.sensors) {
        const line = document.createElement('div');
        const silent = s.silent_s === null || s.silent_s > 0.5;
        line.className = silent ? 'silent' : '';
        line.textContent = `${s.id}: ${s.rate_hz.toFixed(0)} Hz${silent ? (s.silent_s === null ? ', no data' : `, silent ${s.silent_s.toFixed(1)} s`) : ''}`;
        status.appendChild(line);
      }
    }
  };
  socket.onclose = () => { status.prepend(document.createTextNode('session ended · ')); };
}

main().catch((e) => { console.error(e); fail(e && e.message ? e.message : e); });
