// dtd explore: the page's behaviour. Talks to the server's /api; loads nothing from elsewhere.
"use strict";

const VIRIDIS = [
  [68, 1, 84], [72, 40, 120], [62, 74, 137], [49, 104, 142], [38, 130, 142],
  [31, 158, 137], [53, 183, 121], [109, 205, 89], [180, 222, 44], [253, 231, 37],
];
const MARGIN = { left: 56, right: 12, top: 12, bottom: 44 };
const POLL_MS = 5000;

const state = {
  info: null,
  epochs: [],
  epochIndex: 0,
  block: null,
  goal: null,
  sliceLift: 0,
  goalLift: 0,
  map: null,
  dragging: null,
  inFlight: false,
  pending: false,
  mapVersion: 0,
};

const $ = (id) => document.getElementById(id);
const canvas = $("table");
const context = canvas.getContext("2d");

function colour(t) {
  const x = Math.min(Math.max(t, 0), 1) * (VIRIDIS.length - 1);
  const i = Math.min(Math.floor(x), VIRIDIS.length - 2);
  const f = x - i;
  return VIRIDIS[i].map((c, k) => Math.round(c + f * (VIRIDIS[i + 1][k] - c)));
}

function say(text, isError = false) {
  $("status").textContent = text;
  $("status").classList.toggle("error", isError);
}

async function request(url, options) {
  const response = await fetch(url, options);
  const body = await response.json().catch(() => ({ error: `answer ${response.status}` }));
  if (!response.ok) throw new Error(body.error || `answer ${response.status}`);
  return body;
}

// World (x, y) <-> canvas pixels: x to the right, y upwards, one scale for both.
function frame() {
  const table = state.info.table;
  const width = canvas.width - MARGIN.left - MARGIN.right;
  const height = canvas.height - MARGIN.top - MARGIN.bottom;
  const scale = Math.min(width / (table.x[1] - table.x[0]), height / (table.y[1] - table.y[0]));
  return { table, scale, left: MARGIN.left, bottom: MARGIN.top + (table.y[1] - table.y[0]) * scale };
}
function toPixels(point) {
  const f = frame();
  return [f.left + (point[0] - f.table.x[0]) * f.scale, f.bottom - (point[1] - f.table.y[0]) * f.scale];
}
function toWorld(px, py) {
  const f = frame();
  return [f.table.x[0] + (px - f.left) / f.scale, f.table.y[0] + (f.bottom - py) / f.scale];
}
function clampToTable(point) {
  const t = state.info.table;
  return [Math.min(Math.max(point[0], t.x[0]), t.x[1]), Math.min(Math.max(point[1], t.y[0]), t.y[1])];
}

function draw() {
  const f = frame();
  const t = f.table;
  context.clearRect(0, 0, canvas.width, canvas.height);
  const [x0, y1] = toPixels([t.x[0], t.y[1]]);
  const [x1, y0] = toPixels([t.x[1], t.y[0]]);
  context.fillStyle = "#d8cdb8";
  context.fillRect(x0, y1, x1 - x0, y0 - y1);
  const map = state.map;
  if (map) {
    const [low, high] = map.value_range;
    const spread = high - low || 1;
    const cellX = (x1 - x0) / map.xs.length;
    const cellY = (y0 - y1) / map.ys.length;
    for (let i = 0; i < map.ys.length; i++) {
      for (let j = 0; j < map.xs.length; j++) {
        const [r, g, b] = colour((map.values[i][j] - low) / spread);
        context.fillStyle = `rgb(${r},${g},${b})`;
        const [cx, cy] = toPixels([map.xs[j], map.ys[i]]);
        context.fillRect(cx - cellX / 2, cy - cellY / 2, cellX + 0.6, cellY + 0.6);
      }
    }
    const [hx, hy] = toPixels(map.highest);
    context.strokeStyle = "white";
    context.lineWidth = 2;
    context.strokeRect(hx - cellX / 2 - 1, hy - cellY / 2 - 1, cellX + 2, cellY + 2);
  }
  // Axes in world metres.
  context.strokeStyle = "#333";
  context.lineWidth = 1;
  context.strokeRect(x0, y1, x1 - x0, y0 - y1);
  context.fillStyle = "#333";
  context.font = "12px system-ui, sans-serif";
  context.textAlign = "center";
  for (let x = Math.ceil(t.x[0] * 10) / 10; x <= t.x[1] + 1e-9; x += 0.1) {
    const [px] = toPixels([x, t.y[0]]);
    context.fillText(x.toFixed(1), px, y0 + 16);
  }
  context.fillText("x (m, world frame)", (x0 + x1) / 2, y0 + 34);
  context.textAlign = "right";
  for (let y = Math.ceil(t.y[0] * 10) / 10; y <= t.y[1] + 1e-9; y += 0.1) {
    const [, py] = toPixels([t.x[0], y]);
    context.fillText(y.toFixed(1), x0 - 6, py + 4);
  }
  context.save();
  context.translate(14, (y0 + y1) / 2);
  context.rotate(-Math.PI / 2);
  context.textAlign = "center";
  context.fillText("y (m, world frame)", 0, 0);
  context.restore();
  // Block, goal, chosen sub-goal.
  const [bx, by] = toPixels(state.block);
  context.fillStyle = "black";
  context.fillRect(bx - 8, by - 8, 16, 16);
  const [gx, gy] = toPixels(state.goal);
  context.beginPath();
  context.arc(gx, gy, 9, 0, 2 * Math.PI);
  context.fillStyle = "#e00000";
  context.fill();
  context.strokeStyle = "white";
  context.stroke();
  if (map) {
    const [sx, sy] = toPixels(map.subgoal);
    context.strokeStyle = "black";
    context.lineWidth = 6;
    cross(sx, sy);
    context.strokeStyle = "#00e000";
    context.lineWidth = 3.5;
    cross(sx, sy);
  }
}
function cross(x, y) {
  context.beginPath();
  context.moveTo(x - 8, y - 8);
  context.lineTo(x + 8, y + 8);
  context.moveTo(x + 8, y - 8);
  context.lineTo(x - 8, y + 8);
  context.stroke();
}

function drawScale() {
  const scale = $("scale");
  const ctx = scale.getContext("2d");
  for (let i = 0; i < scale.width; i++) {
    const [r, g, b] = colour(i / (scale.width - 1));
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(i, 0, 1, scale.height);
  }
}

const point = (p) => "(" + p.map((v) => v.toFixed(3)).join(", ") + ")";

function currentEpoch() {
  return state.epochs[state.epochIndex];
}

async function refreshMap() {
  if (!state.info || !state.info.map || state.epochs.length === 0) return;
  if (state.inFlight) {
    state.pending = true;
    return;
  }
  state.inFlight = true;
  state.pending = false;
  const table = state.info.table;
  const query = new URLSearchParams({
    epoch: currentEpoch(),
    block_x: state.block[0], block_y: state.block[1],
    goal_x: state.goal[0], goal_y: state.goal[1],
    resolution: state.info.resolution,
  });
  if (state.info.goal_in_air) {
    query.set("goal_z", table.block_z + state.goalLift);
    query.set("z", table.block_z + state.sliceLift);
  }
  const began = performance.now();
  try {
    const map = await request("/api/map?" + query);
    state.map = map;
    state.mapVersion += 1;
    showNumbers(map, performance.now() - began);
    draw();
    say("");
  } catch (error) {
    say(error.message, true);
  } finally {
    state.inFlight = false;
    if (state.pending) refreshMap();
  }
}

function showNumbers(map, elapsed) {
  $("numbers").hidden = false;
  $("block-at").textContent = point(map.block);
  $("goal-at").textContent = point(map.goal);
  $("subgoal-at").textContent = point(map.subgoal);
  $("highest-at").textContent = point(map.highest);
  $("value-range").textContent = `${map.value_range[0].toFixed(3)} to ${map.value_range[1].toFixed(3)}`;
  $("scale-low").textContent = map.value_range[0].toFixed(2);
  $("scale-high").textContent = map.value_range[1].toFixed(2);
  $("map-time").textContent =
    `${elapsed.toFixed(0)} ms (${map.compute_ms.toFixed(0)} ms on the server, ` +
    `${map.xs.length}x${map.ys.length} cells)`;
  canvas.dataset.subgoal = JSON.stringify(map.subgoal);
  canvas.dataset.block = JSON.stringify(map.block);
  canvas.dataset.goal = JSON.stringify(map.goal);
  canvas.dataset.epoch = String(map.epoch);
  canvas.dataset.version = String(state.mapVersion);
  const facts = [`${map.env_steps.toLocaleString("en")} env steps`];
  if (map.eval_success !== null) facts.push(`eval success ${map.eval_success.toFixed(2)}`);
  $("epoch-facts").textContent = facts.join(", ");
}

function setEpochs(epochs) {
  const previous = currentEpoch();
  const followLast = state.epochs.length === 0 || state.epochIndex === state.epochs.length - 1;
  state.epochs = epochs;
  const slider = $("epoch");
  slider.max = Math.max(epochs.length - 1, 0);
  let index = followLast ? epochs.length - 1 : epochs.indexOf(previous);
  if (index < 0) index = epochs.length - 1;
  state.epochIndex = Math.max(index, 0);
  slider.value = state.epochIndex;
  slider.disabled = epochs.length < 2;
  $("epoch-label").textContent = epochs.length ? String(currentEpoch()) : "-";
  $("play").disabled = epochs.length === 0;
  return currentEpoch() !== previous;
}

function describeRun(info) {
  $("run-name").textContent = info.run;
  const progress = info.progress
    ? `trained ${info.progress.epoch} of ${info.epochs_planned} epochs ` +
      `(${info.progress.env_steps.toLocaleString("en")} env steps)`
    : "no epoch finished yet";
  $("run-facts").textContent = `${info.algo} on ${info.env}: ${progress}; ` +
    `${info.epochs.length} epochs kept to look at`;
}

async function poll() {
  try {
    const info = await request("/api/run");
    state.info = info;
    describeRun(info);
    if (info.waiting) say(info.waiting);
    if (setEpochs(info.epochs)) refreshMap();
  } catch (error) {
    say(`the explorer does not answer (${error.message})`, true);
  }
}

function pointerAt(event) {
  const box = canvas.getBoundingClientRect();
  return [(event.clientX - box.left) * canvas.width / box.width, (event.clientY - box.top) * canvas.height / box.height];
}

function startDrag(event) {
  if (!state.info || !state.info.placeable) return;
  const [px, py] = pointerAt(event);
  const near = (p) => Math.hypot(...toPixels(p).map((v, k) => v - [px, py][k]));
  const candidates = [["block", near(state.block)], ["goal", near(state.goal)]].sort((a, b) => a[1] - b[1]);
  if (candidates[0][1] > 20) return;
  state.dragging = candidates[0][0];
  canvas.setPointerCapture(event.pointerId);
  event.preventDefault();
}
function moveDrag(event) {
  if (!state.dragging) return;
  state[state.dragging] = clampToTable(toWorld(...pointerAt(event)));
  draw();
  refreshMap();
}
function endDrag() {
  if (!state.dragging) return;
  state.dragging = null;
  refreshMap();
}

async function play() {
  const button = $("play");
  button.disabled = true;
  say("playing and rendering an episode...");
  const body = { epoch: currentEpoch() };
  if (state.info.placeable) {
    body.block = state.block;
    body.goal = [...state.goal];
    if (state.info.goal_in_air) body.goal.push(state.info.table.block_z + state.goalLift);
  }
  try {
    const episode = await request("/api/episode", {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body),
    });
    const video = $("video");
    video.hidden = false;
    video.src = "/videos/" + episode.video;
    video.dataset.episode = episode.video;
    video.play().catch(() => {});
    showPlan(episode);
    say("");
  } catch (error) {
    say(error.message, true);
  } finally {
    button.disabled = false;
  }
}

function showPlan(episode) {
  const plan = episode.plan;
  const angles = plan.angles;
  const rows = [];
  const outcome = plan.success ? '<span class="success">success</span>' : '<span class="failure">failure</span>';
  rows.push(`<p>Epoch ${episode.epoch}: ${outcome}</p>`);
  rows.push("<table><tr><th></th><th>sub-goal</th><th>reached</th><th>segment ended at</th></tr>");
  rows.push(`<tr><th>start</th><td colspan="3">${point(plan.start)}</td></tr>`);
  (plan.subgoals || []).forEach((subgoal, i) => {
    let turn = "";
    if (angles) {
      turn = `<br>${angles.start_to_subgoal[i].toFixed(0)}&deg; from the start, ` +
        `${angles.subgoal_to_goal[i].toFixed(0)}&deg; from the goal; ended ` +
        `${angles.segment_end_to_subgoal[i].toFixed(0)}&deg; from it`;
    }
    rows.push(`<tr><th>segment ${i + 1}</th><td>${point(subgoal)}${turn}</td>` +
      `<td>${plan.reached[i] ? "yes" : "no"}</td><td>${point(plan.segment_ends[i])}</td></tr>`);
  });
  rows.push(`<tr><th>goal</th><td colspan="3">${point(plan.goal)}</td></tr></table>`);
  $("plan").innerHTML = rows.join("");
}

function onSlider() {
  state.epochIndex = Number($("epoch").value);
  $("epoch-label").textContent = String(currentEpoch());
  refreshMap();
}

function onHeights() {
  state.sliceLift = Number($("slice").value);
  state.goalLift = Number($("goal-height").value);
  const z = state.info.table.block_z;
  $("slice-label").textContent = (z + state.sliceLift).toFixed(2);
  $("goal-height-label").textContent = (z + state.goalLift).toFixed(2);
  refreshMap();
}

async function start() {
  drawScale();
  try {
    state.info = await request("/api/run");
  } catch (error) {
    say(`the explorer does not answer (${error.message})`, true);
    return;
  }
  const info = state.info;
  describeRun(info);
  if (info.placeable) {
    const t = info.table;
    state.block = [t.x[0] + 0.2 * (t.x[1] - t.x[0]), t.y[0] + 0.21 * (t.y[1] - t.y[0])];
    state.goal = [t.x[0] + 0.8 * (t.x[1] - t.x[0]), t.y[0] + 0.79 * (t.y[1] - t.y[0])];
    draw();
    canvas.addEventListener("pointerdown", startDrag);
    canvas.addEventListener("pointermove", moveDrag);
    canvas.addEventListener("pointerup", endDrag);
    canvas.addEventListener("pointercancel", endDrag);
  } else {
    $("map-area").hidden = true;
    $("episode-hint").textContent = "Plays one deterministic episode of the agent of the chosen epoch " +
      `from the task's own random start and renders it: ${info.legend}.`;
  }
  if (!info.map) {
    $("no-map").hidden = false;
    $("no-map").textContent = `No value map: ${info.no_map_reason}.`;
    if (info.placeable) $("map-area").querySelector(".hint").textContent =
      "Drag the black block and the red goal to choose where an episode starts.";
  }
  if (info.goal_in_air) {
    $("height-controls").hidden = false;
    onHeights();
  }
  if (info.waiting) say(info.waiting);
  setEpochs(info.epochs);
  $("epoch").addEventListener("input", onSlider);
  $("slice").addEventListener("input", onHeights);
  $("goal-height").addEventListener("input", onHeights);
  $("play").addEventListener("click", play);
  refreshMap();
  setInterval(poll, POLL_MS);
}

// What the page shows, for a person at the console or a browser test.
window.dtdExplore = { state, toPixels, toWorld };

start();
