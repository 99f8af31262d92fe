// imubake setup: the suit's sensors live, the one that moves lit, each put on a bone of the
// character by a click, the calibrations run from here, and Save.
//
// The server sends the board over /setup ten times a second (JSON: see src/setup/board.rs,
// `Snapshot`) and takes commands back over the same socket ({"cmd": "assign", …}). Units: gyro
// °/s, specific force m/s², the field in the log's unit; the figure in metres, rig world Y up.
//
// `window.imubakeSetup` is a hook for tests: `state` (the last board), `connected`, `send(cmd)`.

const $ = (id) => document.getElementById(id);
const SVG = 'http://www.w3.org/2000/svg';

const hook = { state: null, connected: false, errors: [], send: () => {} };
window.imubakeSetup = hook;

let socket = null;
let selected = null;
let camera = 'front';
let figureKey = '';

function send(cmd) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(cmd));
}
hook.send = send;

// Text from the stream (sensor ids, messages) goes into HTML only escaped.
const esc = (t) =>
  String(t).replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' })[c]);
const fixed = (v, d = 1) => (v === null || v === undefined ? '–' : Number(v).toFixed(d));
const vec = (v, d = 1) => (v ? v.map((x) => fixed(x, d)).join(' ') : '–');

// How far the follow camera has turned (the pelvis sensor's turn since the pose), radians.
let followTurn = 0;

// The figure's 2-D view of a point [x, y, z] (metres, Y up) for the camera. Follow looks from the
// front as the subject turns: the camera goes round the vertical with the pelvis (a turn toward
// east seen from above is clockwise, a turn of −θ about Y).
function project(p) {
  const [x, y, z] = p;
  if (camera === 'side') return [-z, -y];
  if (camera === 'top') return [x, z];
  if (camera === 'follow') {
    const [c, s] = [Math.cos(followTurn), Math.sin(followTurn)];
    return [c * x + s * z, -y];
  }
  return [x, -y];
}

function drawFigure(state) {
  const svg = $('figure');
  const figure = state.figure;
  followTurn = camera === 'follow' ? ((state.pelvis_turn_deg ?? 0) * Math.PI) / 180 : 0;
  const key = camera + Math.round(followTurn * 180) + JSON.stringify(figure.map((j) => j.name));
  const assigned = new Map(state.sensors.filter((s) => s.bone).map((s) => [s.bone, s.id]));
  const litBone = state.sensors.find((s) => s.id === state.lit)?.bone;
  if (key !== figureKey) {
    figureKey = key;
    svg.replaceChildren();
    const segments = [];
    figure.forEach((j, i) => {
      const children = figure.filter((c) => c.parent === i);
      for (const c of children) segments.push([j.name, j.position_m, c.position_m]);
      if (children.length === 0 && j.end_m) segments.push([j.name, j.position_m, j.end_m]);
    });
    const points = segments.flatMap(([, a, b]) => [project(a), project(b)]);
    if (points.length === 0) return;
    const xs = points.map((p) => p[0]);
    const ys = points.map((p) => p[1]);
    const pad = 0.1;
    const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
    svg.setAttribute('viewBox', `${x0 - pad} ${y0 - pad} ${x1 - x0 + 2 * pad} ${y1 - y0 + 2 * pad}`);
    for (const [bone, a, b] of segments) {
      // A bone is a band 4 cm wide along its segment (an area to click, whichever way it lies).
      const [ax, ay] = project(a);
      const [bx, by] = project(b);
      const length = Math.hypot(bx - ax, by - ay) || 1;
      const [nx, ny] = [(-(by - ay) / length) * 0.02, ((bx - ax) / length) * 0.02];
      const band = document.createElementNS(SVG, 'polygon');
      band.setAttribute(
        'points',
        [[ax + nx, ay + ny], [bx + nx, by + ny], [bx - nx, by - ny], [ax - nx, ay - ny]].map((p) => p.join(',')).join(' '),
      );
      band.dataset.bone = bone;
      const title = document.createElementNS(SVG, 'title');
      title.textContent = bone;
      band.appendChild(title);
      band.addEventListener('click', () => {
        if (!selected) {
          showMessage('select a sensor first (move it, or click its row)', true);
          return;
        }
        send({ cmd: 'assign', sensor: selected, bone });
      });
      svg.appendChild(band);
    }
    for (const j of figure) {
      const [x, y] = project(j.position_m);
      const text = document.createElementNS(SVG, 'text');
      text.setAttribute('x', x + 0.02);
      text.setAttribute('y', y - 0.01);
      text.dataset.bone = j.name;
      svg.appendChild(text);
    }
  }
  for (const band of svg.querySelectorAll('polygon')) {
    band.classList.toggle('assigned', assigned.has(band.dataset.bone));
    band.classList.toggle('lit', litBone !== undefined && band.dataset.bone === litBone);
  }
  for (const text of svg.querySelectorAll('text')) {
    text.textContent = assigned.get(text.dataset.bone) ?? '';
  }
}

function drawSensors(state) {
  const body = $('sensors').tBodies[0];
  const rows = new Map([...body.rows].map((r) => [r.dataset.sensor, r]));
  for (const s of state.sensors) {
    let row = rows.get(s.id);
    if (!row) {
      row = body.insertRow();
      row.dataset.sensor = s.id;
      for (let i = 0; i < 10; i++) row.insertCell();
      row.addEventListener('click', () => select(s.id));
    }
    rows.delete(s.id);
    const flags = [];
    if (s.silent_s > 0.5) flags.push(`silent ${fixed(s.silent_s)} s`);
    if (s.accelerating) flags.push('accelerating');
    if (s.magnetic_disturbance) flags.push('magnetic disturbance');
    const cells = [
      esc(s.id),
      esc(s.bone ?? ''),
      fixed(s.rate_hz, 0),
      String(s.gaps),
      fixed(s.turn_dps, 0),
      s.gyr_dps ? `${vec(s.gyr_dps)} |${fixed(s.gyr_norm_dps)}|` : s.q ? `q ${vec(s.q, 3)}` : '–',
      s.acc ? `${vec(s.acc, 2)} |${fixed(s.acc_norm, 2)}|<small>${vec(s.acc_unit, 3)}</small>` : '–',
      s.mag
        ? `${vec(s.mag, 1)} |${fixed(s.mag_norm, 1)}|<small>${vec(s.mag_unit, 3)}${s.mag_coverage_pct === null ? '' : ` · ${fixed(s.mag_coverage_pct, 0)} % covered`}</small>`
        : '–',
      s.fused
        ? `tilt ${fixed(s.fused_tilt_deg)}° heading ${fixed(s.fused_heading_deg)}°<small>${vec(s.fused, 3)}</small>`
        : esc(s.fusion_error ?? '–'),
      `<span class="flag">${esc(flags.join(', '))}</span>`,
    ];
    cells.forEach((html, i) => {
      if (row.cells[i].innerHTML !== html) row.cells[i].innerHTML = html;
    });
    row.classList.toggle('lit', s.id === state.lit);
    row.classList.toggle('selected', s.id === selected);
  }
  for (const row of rows.values()) row.remove();
}

function select(id) {
  selected = id;
  $('selected').textContent = id ? `placing ${id}: click its bone` : 'no sensor selected';
}

function showMessage(text, error) {
  const box = $('message');
  box.hidden = !text;
  box.textContent = text ?? '';
  box.classList.toggle('error', Boolean(error));
}

function drawCalibration(state) {
  const c = state.capture;
  const box = $('capture');
  box.hidden = !c;
  if (c) {
    const what = {
      gyro_bias: 'hold every sensor still',
      magnetometer: 'turn every sensor through all directions',
      pose: 'hold the pose',
      second_pose: 'hold the second pose',
      bow: 'bow forward and come back',
    }[c.kind];
    box.textContent = c.starts_in_s > 0 ? `${what} in ${c.starts_in_s.toFixed(1)} s` : `${what}: ${c.left_s.toFixed(1)} s`;
  }
  const bias = $('bias-result');
  bias.innerHTML = state.bias
    .map((b) =>
      b.bias.Ok
        ? `<tr><td>${esc(b.sensor)}</td><td>${vec(b.bias.Ok.bias_rad_s.map((x) => (x * 180) / Math.PI), 3)} °/s</td><td>± ${fixed(Math.max(...b.bias.Ok.uncertainty_dps), 3)}</td></tr>`
        : `<tr class="error"><td>${esc(b.sensor)}</td><td colspan="2">${esc(b.bias.Err)}</td></tr>`,
    )
    .join('');
  $('mag-result').innerHTML = state.mag
    .map((m) =>
      m.fit.Ok
        ? `<tr><td>${esc(m.sensor)}</td><td>covered ${fixed(m.fit.Ok.coverage_pct, 0)} %</td><td>norm spread ${fixed(m.fit.Ok.residual_before_pct, 1)} → ${fixed(m.fit.Ok.residual_after_pct, 1)} %</td></tr>`
        : `<tr class="error"><td>${esc(m.sensor)}</td><td colspan="2">${esc(m.fit.Err)}</td></tr>`,
    )
    .join('');
  $('segments-now').textContent = Object.entries(state.segments)
    .map(([k, v]) => `${k} ${v} m`)
    .join(' · ');
  const held = state.pose_held;
  $('pose-result').textContent = held
    ? held.moved.length
      ? `moved during the pose: ${held.moved.join(', ')} — hold it again`
      : `held ${held.seconds} s from t = ${held.start_s.toFixed(2)} s, every sensor still`
    : '';
  $('second-result').textContent = state.second_held
    ? `held ${state.second_held.seconds} s, ${(state.second_held.start_s - (held?.start_s ?? 0)).toFixed(2)} s after the first began${state.second_held.moved.length ? `; moved: ${state.second_held.moved.join(', ')}` : ''} — start each take with both poses in this timing`
    : '';
  const names = state.poses.includes('rest') ? state.poses : ['rest', ...state.poses];
  const second = $('second-pose');
  if (second.options.length !== names.length + 1) {
    second.replaceChildren(new Option('none', ''), ...names.map((n) => new Option(n, n)));
  }
  if (document.activeElement !== second) second.value = state.second_pose ?? '';
  const bow = state.bow;
  $('bow-result').textContent = bow
    ? bow.error
      ? bow.error
      : `${bow.sensor} faces ${bow.forward} (${fixed(bow.off_axis_deg)}° off that axis; bowed ${fixed(bow.bow_deg, 0)}°)`
    : '';
  $('height-now').textContent = state.height_m ? `${state.height_m} m` : '';
  const pose = $('pose');
  if (pose.options.length !== names.length) {
    pose.replaceChildren(...names.map((n) => new Option(n, n)));
  }
  if (document.activeElement !== pose) pose.value = state.pose;
}

function draw(state) {
  hook.state = state;
  $('stream').textContent = state.now_s === null
    ? 'waiting for the stream…'
    : `t = ${state.now_s.toFixed(2)} s · ${state.sensors.length} sensors${state.refused_sensors ? ` · ${state.refused_sensors} samples of sensors past the limit` : ''}`;
  if ($('follow-lit').checked && state.lit && state.lit !== selected) select(state.lit);
  drawSensors(state);
  drawFigure(state);
  drawCalibration(state);
  if (state.message !== null) showMessage(state.message, state.message.startsWith('error'));
}

function connect() {
  socket = new WebSocket(`ws://${location.host}/setup`);
  socket.addEventListener('open', () => {
    hook.connected = true;
    $('connection').textContent = 'connected';
  });
  socket.addEventListener('message', (e) => {
    try {
      draw(JSON.parse(e.data));
    } catch (err) {
      hook.errors.push(String(err));
    }
  });
  socket.addEventListener('close', () => {
    hook.connected = false;
    $('connection').textContent = 'disconnected: retrying…';
    setTimeout(connect, 1000);
  });
}

$('bias').addEventListener('click', () => send({ cmd: 'capture', kind: 'gyro_bias', seconds: 3, countdown_s: 0 }));
$('hold').addEventListener('click', () => send({ cmd: 'capture', kind: 'pose', seconds: 2, countdown_s: 3 }));
$('bow').addEventListener('click', () => send({ cmd: 'capture', kind: 'bow', seconds: 4, countdown_s: 2 }));
$('mag').addEventListener('click', () => send({ cmd: 'capture', kind: 'magnetometer', seconds: 15, countdown_s: 0 }));
$('set-segment').addEventListener('click', () => {
  const m = $('segment-m').value;
  send({ cmd: 'segment', part: $('segment-part').value, m: m === '' ? null : Number(m) });
});
$('hold-second').addEventListener('click', () => send({ cmd: 'capture', kind: 'second_pose', seconds: 2, countdown_s: 2 }));
$('second-pose').addEventListener('change', (e) => send({ cmd: 'second_pose', name: e.target.value || null }));
$('pose').addEventListener('change', (e) => send({ cmd: 'pose', name: e.target.value }));
$('set-height').addEventListener('click', () => send({ cmd: 'height', m: Number($('height').value) }));
$('save').addEventListener('click', () => send({ cmd: 'save' }));
for (const b of document.querySelectorAll('#cameras button')) {
  b.addEventListener('click', () => {
    camera = b.dataset.camera;
    for (const o of document.querySelectorAll('#cameras button')) o.classList.toggle('on', o === b);
    if (hook.state) drawFigure(hook.state);
  });
}
window.addEventListener('error', (e) => hook.errors.push(String(e.message)));
connect();
