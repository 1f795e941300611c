// planHRC cell console: reads the knowledge-base service's JSON API and its event stream; posts only goals and
// perceptions (it never takes an action for execution: that is the worker's). No build step, no libraries.
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";
const DECISIONS = new Set(["goal_reached", "continue", "resume", "replan", "no_plan"]);
const TOKEN_KEY = "planhrc-console-token";

const view = {
  objects: [], objectId: null, obj: null, perceived: null, goal: null, plan: null,
  viewStep: null, draft: null, lastSeq: 0, stream: null, retry: null, refreshTimer: null,
  // what the log needs to tell who changed the object
  lastJoints: null, feedbackSince: null, queue: Promise.resolve(), auth: false,
};

const $ = (id) => document.getElementById(id);

// -- HTTP ---------------------------------------------------------------------------------------------------
class ApiError extends Error {}

async function api(method, path, body) {
  const headers = { Accept: "application/json" };
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const token = $("token").value.trim();
  if (token) headers.Authorization = `Bearer ${token}`;
  let response;
  try {
    response = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  } catch (err) {
    setService(false);
    throw new ApiError(`the service does not answer (${err.message})`);
  }
  setService(true);
  const text = await response.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch (_) { data = text; }
  if (!response.ok) {
    const detail = data && typeof data === "object" && "detail" in data ? data.detail : text;
    throw new ApiError(typeof detail === "string" ? detail : JSON.stringify(detail));
  }
  return data;
}

async function apiOrNull(path) {
  try { return await api("GET", path); } catch (err) { return null; }
}

function setService(up) {
  const pill = $("service");
  pill.textContent = up ? (view.auth ? "service up · writes need a token" : "service up") : "service unreachable";
  pill.className = "pill " + (up ? "ok" : "down");
}

// -- geometry -----------------------------------------------------------------------------------------------
const norm = (a) => ((a % 360) + 360) % 360;

// Orientation of every link from a stored state, in degrees clockwise seen from above.
// Relative: joints carry θ(k+1) − θk and l1 is not tracked (it is taken from `reference`); absolute: jK carries θK;
// bimanual: jK carries θ(K+1) − θ1 (l1 from `reference` again). A joint the state leaves free (a partial goal) keeps
// the reference's value.
function linkAngles(obj, state, reference) {
  if (!obj || !state) return null;
  if (state.link_orientations_deg) return state.link_orientations_deg.slice();
  const n = obj.links.length;
  const ref = reference || new Array(n).fill(0);
  const values = state.joint_values_deg || {};
  const out = new Array(n);
  if (obj.formulation === "absolute") {
    for (let k = 0; k < n; k++) {
      const v = values[obj.joints[k]];
      out[k] = v === undefined ? ref[k] : v;
    }
  } else if (obj.formulation === "bimanual") {
    out[0] = ref[0];
    for (let k = 1; k < n; k++) {
      const v = values[obj.joints[k - 1]];
      out[k] = v === undefined ? ref[k] : ref[0] + v;
    }
  } else {
    out[0] = ref[0];
    for (let k = 1; k < n; k++) {
      const v = values[obj.joints[k - 1]];
      out[k] = out[k - 1] + (v === undefined ? ref[k] - ref[k - 1] : v);
    }
  }
  return out.map(norm);
}

// Joint positions in metres on the page's axes: x to the robot's right, y down (the robot's forward axis is up).
function chainPoints(obj, angles) {
  const pts = [[0, 0]];
  obj.links.forEach((link, k) => {
    const [x, y] = pts[k];
    const a = (angles[k] * Math.PI) / 180;  // clockwise from the robot's forward axis (up on the page)
    pts.push([x + link.length_m * Math.sin(a), y - link.length_m * Math.cos(a)]);
  });
  return pts;
}

const shortName = (name) => name.replace(/^.*_/, "");

function svg(tag, attrs, parent, text) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (text !== undefined) el.textContent = text;
  if (parent) parent.appendChild(el);
  return el;
}

// -- drawing ------------------------------------------------------------------------------------------------
function perceivedAngles() { return linkAngles(view.obj, view.perceived, null); }

// The perceived orientations snapped to the allowed ones: what the planner saw, the reference of other states.
function snappedAngles() {
  const angles = perceivedAngles(), step = view.obj && view.obj.step_deg;
  return angles && step ? angles.map((a) => norm(Math.round(a / step) * step)) : angles;
}

function goalAngles() {
  if (view.draft) return view.draft;
  return linkAngles(view.obj, view.goal, snappedAngles());
}

function expectedState() {
  const plan = view.plan, ex = view.obj && view.obj.execution;
  if (!plan) return null;
  if (view.viewStep !== null) return plan.expected_states[view.viewStep] || null;  // s^e after step viewStep
  if (!ex || ex.plan_id !== plan.id || ex.next_step === null) return null;
  return plan.expected_states[ex.next_step] || null;  // s^e_{next+1}: after the next action
}

function draw() {
  const root = $("drawing");
  root.replaceChildren();
  const obj = view.obj;
  if (!obj) return;
  const perceived = perceivedAngles();
  const goal = goalAngles();
  const expected = linkAngles(obj, expectedState(), snappedAngles());
  // Fit what is drawn (every chain and the base) to the drawing, in screen pixels, with room for the labels.
  const W = root.clientWidth || 600, H = root.clientHeight || 420;
  root.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const all = [perceived, goal, expected].filter(Boolean).flatMap((a) => chainPoints(obj, a)).concat([[0, 0]]);
  const xs = all.map((p) => p[0]), ys = all.map((p) => p[1]);
  const minX = Math.min(...xs), maxX = Math.max(...xs), minY = Math.min(...ys), maxY = Math.max(...ys);
  const scale = Math.min((W - 170) / Math.max(maxX - minX, 1e-6), (H - 90) / Math.max(maxY - minY, 1e-6),
                         (0.45 * H) / obj.links.reduce((sum, l) => sum + l.length_m, 0) * 2);
  const ox = W / 2 - scale * (minX + maxX) / 2, oy = H / 2 - scale * (minY + maxY) / 2;
  const screen = (angles) => chainPoints(obj, angles).map(([x, y]) => [ox + scale * x, oy + scale * y]);
  svg("line", { x1: ox, y1: H - 4, x2: ox, y2: 4, class: "axis" }, root);
  svg("text", { x: ox + 4, y: 16, class: "axis-label" }, root, "robot forward (0°)");
  svg("circle", { cx: ox, cy: oy, r: 7, class: "base" }, root);
  const layers = [
    [goal, "goal" + (view.draft ? " draft" : ""), 16],
    [expected, "expected", 11],
    [perceived, "perceived", 6],
  ];
  for (const [angles, cls, width] of layers) {
    if (!angles) continue;
    const pts = screen(angles);
    const g = svg("g", { class: cls.split(" ")[0] + "-layer" }, root);
    angles.forEach((a, k) => {
      // a bar (not a line: a vertical line has an empty box and cannot be hit), rotated from the page's x axis
      const len = Math.hypot(pts[k + 1][0] - pts[k][0], pts[k + 1][1] - pts[k][1]);
      const line = svg("rect", { x: 0, y: -width / 2, width: len, height: width, rx: width / 2, class: `link ${cls}`,
                                 transform: `translate(${pts[k][0]} ${pts[k][1]}) rotate(${a - 90})`, "data-link": k }, g);
      if (cls.startsWith("goal")) {
        line.addEventListener("click", (ev) => turnDraftLink(k, ev.shiftKey ? -1 : 1));
        svg("title", {}, line, `turn ${shortName(obj.links[k].name)} (and the links after it) one step`);
      }
    });
    if (cls === "perceived") {
      pts.slice(1, -1).forEach(([x, y]) => svg("circle", { cx: x, cy: y, r: 4, class: "joint" }, g));
      angles.forEach((a, k) => {
        const [x0, y0] = pts[k], [x1, y1] = pts[k + 1];
        svg("text", { x: (x0 + x1) / 2 + 8, y: (y0 + y1) / 2 - 8 }, g, `${shortName(obj.links[k].name)} ${a.toFixed(0)}°`);
      });
    }
  }
  drawAngleTable(perceived, goal, expected);
}

function drawAngleTable(perceived, goal, expected) {
  const obj = view.obj, table = $("angles");
  table.replaceChildren();
  const head = table.insertRow();
  ["", ...obj.links.map((l) => shortName(l.name))].forEach((t) => { const th = document.createElement("th"); th.textContent = t; head.appendChild(th); });
  const rows = [["perceived", perceived], [view.draft ? "goal (draft)" : "goal", goal],
                [view.viewStep !== null ? `expected after a_${view.viewStep}` : "expected next", expected]];
  for (const [label, angles] of rows) {
    const row = table.insertRow();
    row.insertCell().textContent = label;
    obj.links.forEach((_, k) => { row.insertCell().textContent = angles ? `${Number(angles[k]).toFixed(angles === perceived ? 1 : 0)}°` : "–"; });
  }
}

function turnDraftLink(k, sign) {
  const obj = view.obj;
  const base = goalAngles() || perceivedAngles() || new Array(obj.links.length).fill(0);
  view.draft = base.map((a, i) => (i >= k ? norm(Math.round(a + sign * obj.step_deg)) : norm(Math.round(a))));
  $("goal-kind").value = "link_orientations_deg";
  fillGoalInputs();
  draw();
}

// -- plan ---------------------------------------------------------------------------------------------------
// A bimanual plan's steps that turn nothing say what they do (centre, grasp, release); every other step turns.
const HAND_STEPS = {movetocentre: "centre the hands on", grasplinks: "grasp", releaselinks: "release"};

function stepWords(s) {
  const pair = [s.held_link_index, s.turned_link_index].filter((k) => k > 0).sort((a, b) => a - b).map((k) => `l${k}`).join(" and ");
  if (s.name === "movetocentre") return `${HAND_STEPS[s.name]} joint j${s.joint_index} (${pair})`;
  if (s.name in HAND_STEPS) return `${HAND_STEPS[s.name]} ${pair} at joint j${s.joint_index}`;
  const dir = s.delta_deg > 0 ? "clockwise" : "anticlockwise";
  const held = s.held_link_index === 0 ? "table" : `l${s.held_link_index}`;
  return `joint j${s.joint_index}, hold ${held}, turn l${s.turned_link_index} ${dir} ${Math.abs(s.delta_deg)}°`;
}

function drawPlan() {
  const list = $("plan");
  list.replaceChildren();
  const plan = view.plan, ex = view.obj && view.obj.execution;
  if (!plan) { $("plan-meta").textContent = "none yet"; return; }
  const following = ex && ex.plan_id === plan.id;
  const status = ex ? ex.status : "";
  const n = plan.steps.length;
  $("plan-meta").textContent = `${plan.id} · ${n} step${n === 1 ? "" : "s"} · ${plan.planner}` + (following ? ` · ${status}` : " · not followed");
  for (const s of plan.steps) {
    const li = document.createElement("li");
    li.textContent = `a_${s.step} ${s.name}: ${stepWords(s)}`;
    li.dataset.step = s.step;
    const done = following && (status === "goal_reached" || (ex.next_step !== null && s.step < ex.next_step));
    if (done) li.classList.add("done");
    if (following && ex.next_step === s.step && status !== "goal_reached") li.classList.add("current");
    if (view.viewStep === s.step) li.classList.add("viewing");
    li.addEventListener("click", () => viewStep(view.viewStep === s.step ? null : s.step));
    list.appendChild(li);
  }
  $("expected-label").textContent = view.viewStep !== null ? `expected after a_${view.viewStep}` : "expected after the next action";
}

// -- objects ------------------------------------------------------------------------------------------------
async function loadObjects() {
  const health = await apiOrNull("health");
  if (health) { view.auth = health.auth; setService(true); }
  let objects;
  try {
    objects = await api("GET", "objects");
  } catch (err) {
    $("error").textContent = err.message;  // e.g. reads need the token on this service
    return;
  }
  view.objects = objects;
  const list = $("objects");
  list.replaceChildren();
  for (const o of objects) {
    const li = document.createElement("li");
    const b = document.createElement("button");
    b.type = "button";
    b.dataset.objectId = o.id;
    b.textContent = `${o.id} ${o.name}`;
    const small = document.createElement("small");
    small.textContent = `${o.formulation} · ${o.links.length} links · K=${o.orientations} · ${o.execution.status}`;
    b.appendChild(small);
    if (o.id === view.objectId) b.classList.add("selected");
    b.addEventListener("click", () => selectObject(o.id));
    li.appendChild(b);
    list.appendChild(li);
  }
  const wanted = new URLSearchParams(location.search).get("object");
  if (!view.objectId && objects.length) selectObject(objects.some((o) => o.id === wanted) ? wanted : objects[0].id);
}

function selectObject(id) {
  if (view.stream) view.stream.abort();
  clearTimeout(view.retry);
  Object.assign(view, { objectId: id, obj: null, perceived: null, goal: null, plan: null, viewStep: null,
                        draft: null, lastSeq: 0, lastJoints: null, feedbackSince: null, queue: Promise.resolve() });
  history.replaceState(null, "", `?object=${encodeURIComponent(id)}`);
  document.querySelectorAll("#objects button").forEach((b) => b.classList.toggle("selected", b.dataset.objectId === id));
  $("log").replaceChildren();
  $("error").textContent = "";
  refresh().then(() => { fillGoalInputs(); fillPerceptionInputs(); });
  connect();
}

async function refresh() {
  const id = view.objectId;
  if (!id) return;
  const obj = await apiOrNull(`objects/${id}`);
  if (!obj || id !== view.objectId) return;
  view.obj = obj;
  const goalChanged = (view.goal ? view.goal.id : null) !== obj.goal_state_id;
  view.goal = obj.goal_state_id ? await apiOrNull(`states/${obj.goal_state_id}`) : null;
  if (goalChanged && !view.draft && !$("goal-inputs").contains(document.activeElement)) fillGoalInputs();
  view.plan = await apiOrNull(`objects/${id}/plan`);
  const ex = obj.execution;
  $("object-title").textContent = `${obj.id} ${obj.name} — ${obj.formulation}, ${obj.links.length} links, K=${obj.orientations} (${obj.step_deg}° a step)`;
  $("object-status").textContent = `execution: ${ex.status}` + (ex.plan_id ? ` · plan ${ex.plan_id}` : "") +
    (ex.next_step ? ` · next step a_${ex.next_step}` : "") + (ex.dispatched_action_id ? ` · dispatched ${ex.dispatched_action_id}` : "");
  const small = document.querySelector(`#objects button[data-object-id="${id}"] small`);
  if (small) small.textContent = `${obj.formulation} · ${obj.links.length} links · K=${obj.orientations} · ${ex.status}`;
  if ($("goal-inputs").children.length === 0) fillGoalInputs();
  if ($("perception-inputs").children.length === 0) fillPerceptionInputs();
  drawPlan();
  draw();
}

function scheduleRefresh() {
  clearTimeout(view.refreshTimer);
  view.refreshTimer = setTimeout(refresh, 60);
}

// -- the decision log over Server-Sent Events ---------------------------------------------------------------
// The stream is read with fetch (not EventSource) so it can carry the bearer token when the service protects
// reads. After a cut (a restart of the service, a network hiccup) it reconnects and sends Last-Event-ID: the
// service then sends only what the page has not shown.
function connect() {
  const id = view.objectId;
  if (!id) return;
  const controller = new AbortController();
  view.stream = controller;
  $("stream").textContent = "connecting…";
  const headers = { Accept: "text/event-stream" };
  const token = $("token").value.trim();
  if (token) headers.Authorization = `Bearer ${token}`;
  if (view.lastSeq > 0) headers["Last-Event-ID"] = String(view.lastSeq);
  const retry = (why) => {
    if (controller.signal.aborted || view.objectId !== id) return;
    $("stream").textContent = why;
    clearTimeout(view.retry);
    view.retry = setTimeout(() => { if (view.objectId === id) connect(); }, 1000);
  };
  fetch(`objects/${encodeURIComponent(id)}/events/stream`, { headers, signal: controller.signal, cache: "no-store" })
    .then(async (response) => {
      if (!response.ok) {
        let detail = `HTTP ${response.status}`;
        try { detail = (await response.json()).detail || detail; } catch (_) { /* not JSON */ }
        setService(true);
        $("error").textContent = detail;
        retry("not streaming: " + detail);
        return;
      }
      setService(true);
      $("stream").textContent = "live";
      loadObjects();
      scheduleRefresh();
      const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
      let buffer = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += value.replace(/\r\n/g, "\n");
        let cut;
        while ((cut = buffer.indexOf("\n\n")) >= 0) {
          onFrame(buffer.slice(0, cut));
          buffer = buffer.slice(cut + 2);
        }
      }
      retry("reconnecting…");
    })
    .catch(() => { setService(false); retry("reconnecting…"); });
}

function onFrame(frame) {
  const data = frame.split("\n").filter((l) => l.startsWith("data:")).map((l) => l.slice(5).trimStart()).join("\n");
  if (!data) return;  // a comment (keep-alive)
  const event = JSON.parse(data);
  if (event.object_id !== view.objectId || event.seq <= view.lastSeq) return;
  view.lastSeq = event.seq;
  view.queue = view.queue.then(() => logEvent(event)).catch((err) => console.error(err));
  scheduleRefresh();
}

// Who changed the object between two perceptions: the robot (a feedback came in, with its outcome) or a human
// (the perceived configuration changed and no robot action explains it).
async function actorOf(event) {
  const stateId = event.data.perceived_state_id;
  const state = stateId ? await apiOrNull(`states/${stateId}`) : null;
  const joints = state ? JSON.stringify(state.joint_values_deg) : null;
  const before = view.lastJoints, feedback = view.feedbackSince;
  view.lastJoints = joints;
  view.feedbackSince = null;
  if (before === null) return ["", "first perception of the object"];
  if (joints === before) {
    return feedback ? ["robot", `robot: a_${feedback.step} ${feedback.outcome}, the object did not change`] : ["", "nothing changed"];
  }
  if (feedback && feedback.outcome !== "failed") {
    const off = event.kind === "resume" || event.kind === "replan" ? " — not where the plan expected" : "";
    return ["robot", `robot: a_${feedback.step} ${feedback.outcome}${off}`];
  }
  const why = feedback ? `a_${feedback.step} failed, yet the object changed` : "no robot action explains this change";
  return ["human", `human: ${why}`];
}

async function logEvent(event) {
  const li = document.createElement("li");
  li.className = event.kind;
  li.dataset.seq = event.seq;
  let actor = null;
  if (DECISIONS.has(event.kind)) actor = await actorOf(event);
  else if (event.kind === "feedback") {
    view.feedbackSince = event.data;
    actor = ["robot", `robot: a_${event.data.step} ${event.data.outcome}` + (event.data.accepted === "late" ? " (late)" : "")];
    if (event.data.outcome !== "succeeded") li.classList.add("failure");
  } else if (event.kind === "goal_set") actor = ["", "operator or task: a new goal"];
  else if (event.kind === "dispatched") actor = ["robot", `robot took a_${event.data.step}`];
  if (event.kind === "no_plan" || (event.data && event.data.planning_status && event.data.planning_status !== "solved")) li.classList.add("failure");
  const seq = document.createElement("span"); seq.className = "seq"; seq.textContent = `#${event.seq} ${new Date(event.created_at * 1000).toLocaleTimeString()}`;
  const kind = document.createElement("span"); kind.className = "kind"; kind.textContent = event.kind.replace("_", " ");
  const reason = document.createElement("span"); reason.className = "reason"; reason.textContent = event.reason;
  li.append(seq, kind, reason);
  if (event.client) {  // the client (API key's name) whose request caused the event
    const client = document.createElement("span"); client.className = "client"; client.textContent = `by ${event.client}`;
    li.appendChild(client);
  }
  if (actor) {
    const who = document.createElement("span");
    who.className = `actor ${actor[0]}`;
    who.textContent = actor[1];
    li.appendChild(who);
  }
  if (DECISIONS.has(event.kind) && event.data.perceived_state_id) addWhyNot(li, event);
  const log = $("log");
  log.prepend(li);  // newest first
  if (DECISIONS.has(event.kind) && event.data.perceived_state_id) {
    const state = await apiOrNull(`states/${event.data.perceived_state_id}`);
    if (state && event.object_id === view.objectId) { view.perceived = state; fillPerceptionInputs(); draw(); }
  }
}

// -- operator panel -----------------------------------------------------------------------------------------
function numberInput(container, label, value, name) {
  const wrap = document.createElement("label");
  wrap.textContent = label;
  const input = document.createElement("input");
  input.type = "text";
  input.inputMode = "decimal";
  input.name = name;
  input.value = value === null || value === undefined ? "" : String(value);
  wrap.appendChild(input);
  container.appendChild(wrap);
  return input;
}

function fillGoalInputs() {
  const obj = view.obj, box = $("goal-inputs");
  box.replaceChildren();
  if (!obj) return;
  const byLinks = $("goal-kind").value === "link_orientations_deg";
  if (byLinks) {
    const angles = goalAngles() || perceivedAngles() || new Array(obj.links.length).fill(0);
    obj.links.forEach((l, k) => numberInput(box, shortName(l.name), Math.round(angles[k]), `goal-${k}`));
  } else {
    const values = (view.goal && view.goal.joint_values_deg) || {};
    obj.joints.forEach((j, k) => numberInput(box, shortName(j), values[j], `goal-${k}`));
  }
}

function fillPerceptionInputs() {
  const obj = view.obj, box = $("perception-inputs");
  if (!obj) return;
  if (box.contains(document.activeElement)) return;  // do not overwrite what a person is typing
  box.replaceChildren();
  const angles = perceivedAngles() || new Array(obj.links.length).fill(0);
  obj.links.forEach((l, k) => numberInput(box, shortName(l.name), Number(angles[k]).toFixed(1).replace(/\.0$/, ""), `perceived-${k}`));
}

// Values as typed: a number stays a number, an empty field is null, anything else goes to the API as written,
// so the service's own message names the field.
function readInputs(box) {
  return Array.from(box.querySelectorAll("input")).map((input) => {
    const text = input.value.trim();
    if (text === "") return null;
    const n = Number(text);
    return Number.isFinite(n) ? n : text;
  });
}

async function submit(form, action) {
  $("error").textContent = "";
  $("notice").textContent = "";
  const buttons = form.querySelectorAll("button");
  buttons.forEach((b) => { b.disabled = true; });
  try {
    $("notice").textContent = await action();
  } catch (err) {
    $("error").textContent = err instanceof ApiError ? err.message : String(err);
  } finally {
    buttons.forEach((b) => { b.disabled = false; });
  }
}

function viewStep(step) {
  view.viewStep = step;
  drawPlan();
  draw();
}

function setupPlanSteps() {
  const n = () => (view.plan ? view.plan.steps.length : 0);
  const current = () => (view.viewStep !== null ? view.viewStep
    : (view.obj && view.obj.execution.next_step) || 1);
  $("step-prev").addEventListener("click", () => { if (n()) viewStep(Math.max(1, current() - (view.viewStep === null ? 0 : 1))); });
  $("step-next").addEventListener("click", () => { if (n()) viewStep(Math.min(n(), current() + (view.viewStep === null ? 0 : 1))); });
  $("step-live").addEventListener("click", () => viewStep(null));
}

function setupOperator() {
  const token = $("token");
  token.value = localStorage.getItem(TOKEN_KEY) || "";
  token.addEventListener("change", () => {
    localStorage.setItem(TOKEN_KEY, token.value.trim());
    $("error").textContent = "";
    if (view.objectId) { if (view.stream) view.stream.abort(); connect(); } else loadObjects();
  });
  $("goal-kind").addEventListener("change", fillGoalInputs);
  $("goal-reset").addEventListener("click", () => { view.draft = null; fillGoalInputs(); draw(); });
  $("goal-inputs").addEventListener("input", () => {
    if ($("goal-kind").value !== "link_orientations_deg") return;
    const values = readInputs($("goal-inputs"));
    if (values.every((v) => typeof v === "number")) { view.draft = values.map(norm); draw(); }
  });
  $("goal-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    if (!view.objectId) return;
    submit($("goal-form"), async () => {
      const body = { [$("goal-kind").value]: readInputs($("goal-inputs")) };
      const answer = await api("PUT", `objects/${view.objectId}/goal`, body);
      view.draft = null;
      await refresh();
      return `goal ${answer.goal_state_id} set` + (answer.problem_id ? ` (problem ${answer.problem_id})` : "; planning waits for the next perception");
    });
  });
  $("perception-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    if (!view.objectId) return;
    submit($("perception-form"), async () => {
      const answer = await api("POST", `objects/${view.objectId}/perceptions`, { link_orientations_deg: readInputs($("perception-inputs")) });
      return `${answer.decision}: ${answer.reason}`;
    });
  });
}

// -- "why not?": the subsumption of a decision's perceived state by the goal and the expected state ------------
function addWhyNot(li, event) {
  const button = document.createElement("button");
  button.type = "button";
  button.className = "why-button";
  button.textContent = "why not?";
  button.title = "is the perceived state within the goal and the state the plan expects? which atoms are missing?";
  const out = document.createElement("ul");
  out.className = "why-not";
  button.addEventListener("click", async () => {
    out.replaceChildren();
    const targets = [];
    if (view.obj && view.obj.goal_state_id) targets.push(["goal", view.obj.goal_state_id]);
    const plan = view.plan, step = event.data.next_step;
    if (plan && plan.id === event.data.plan_id && step && plan.expected_states[step - 1]) {
      targets.push([`expected state s^e_${step}`, plan.expected_states[step - 1].id]);
    }
    if (!targets.length) { whyLine(out, "no goal to compare with", "error"); return; }
    for (const [label, id] of targets) {
      try {
        const a = await api("GET", `states/${encodeURIComponent(event.data.perceived_state_id)}/subsumed-by/${encodeURIComponent(id)}`);
        if (a.subsumed) { whyLine(out, `within the ${label} (${a.atoms_checked} atoms hold)`, "ok"); continue; }
        const joints = a.differs.map((d) => `${shortName(d.joint)} is ${d.has ? d.has.replace("deg_", "") + "°" : "unknown"}, wants ${d.wants.replace("deg_", "")}°`);
        whyLine(out, `not within the ${label}: ${a.missing.length} of ${a.atoms_checked} atoms missing — ${joints.join("; ") || a.missing.join(" ")}`, "missing");
      } catch (err) {
        whyLine(out, err.message, "error");
      }
    }
  });
  li.append(button, out);
}

function whyLine(list, text, cls) {
  const item = document.createElement("li");
  item.className = cls;
  item.textContent = text;
  list.appendChild(item);
}

// -- the query panel ----------------------------------------------------------------------------------------
const QUERY_EXAMPLES = [
  ["current state of every object", `SELECT ?object ?joint ?degrees WHERE {
  { SELECT ?object (MAX(?t) AS ?latest) WHERE {
      ?s a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?t } GROUP BY ?object }
  ?state a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?latest ; planhrc:madeof ?p .
  ?p a planhrc:HasOrientation ; planhrc:arg1 ?joint ; planhrc:arg2 ?o . ?o planhrc:degrees ?degrees .
} ORDER BY ?object ?joint`],
  ["goal of every object", `SELECT ?object ?joint ?degrees WHERE {
  ?state a planhrc:GoalState ; planhrc:stateOf ?object ; planhrc:madeof ?p .
  ?p a planhrc:HasOrientation ; planhrc:arg1 ?joint ; planhrc:arg2 ?o . ?o planhrc:degrees ?degrees .
} ORDER BY ?object ?joint`],
  ["turning a joint moves (entailed chain)", `SELECT ?joint ?turns ?affects WHERE {
  ?joint planhrc:turns ?turns ; planhrc:affectsJoint ?affects .
} ORDER BY ?joint ?affects`],
  ["relative angles of the latest perceptions (SWRL)", `SELECT ?observation ?relative WHERE {
  ?observation planhrc:relativeOrientation ?o . ?o planhrc:degrees ?relative .
} ORDER BY ?observation`],
  ["facts in each graph", `SELECT ?graph (COUNT(*) AS ?facts) WHERE { GRAPH ?graph { ?s ?p ?o } } GROUP BY ?graph`],
];

function setupQueries() {
  const select = $("query-example");
  QUERY_EXAMPLES.forEach(([label], i) => {
    const option = document.createElement("option");
    option.value = String(i);
    option.textContent = label;
    select.appendChild(option);
  });
  const pick = () => { $("query-text").value = QUERY_EXAMPLES[Number(select.value)][1]; };
  select.addEventListener("change", pick);
  pick();
  $("query-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    $("query-error").textContent = "";
    $("query-status").textContent = "running…";
    $("query-result").replaceChildren();
    const headers = { Accept: "application/sparql-results+json", "Content-Type": "application/x-www-form-urlencoded" };
    const token = $("token").value.trim();
    if (token) headers.Authorization = `Bearer ${token}`;
    const started = performance.now();
    try {
      const response = await fetch("sparql", { method: "POST", headers, body: new URLSearchParams({ query: $("query-text").value }) });
      const data = await response.json();
      if (!response.ok) throw new ApiError(data.detail || `HTTP ${response.status}`);
      showResults(data, performance.now() - started);
    } catch (err) {
      $("query-status").textContent = "";
      $("query-error").textContent = err.message;
    }
  });
}

function showResults(data, ms) {
  const box = $("query-result");
  if ("boolean" in data) {
    box.textContent = data.boolean ? "yes" : "no";
    $("query-status").textContent = `answered in ${ms.toFixed(0)} ms`;
    return;
  }
  const vars = data.head.vars, rows = data.results.bindings;
  const table = document.createElement("table");
  const head = table.insertRow();
  vars.forEach((v) => { const th = document.createElement("th"); th.textContent = v; head.appendChild(th); });
  for (const row of rows) {
    const tr = table.insertRow();
    vars.forEach((v) => { tr.insertCell().textContent = row[v] ? row[v].value.replace(/^.*[#/]/, (m) => (row[v].type === "uri" ? "" : m)) : ""; });
  }
  box.appendChild(table);
  $("query-status").textContent = `${rows.length} row${rows.length === 1 ? "" : "s"} in ${ms.toFixed(0)} ms`;
}

setupOperator();
setupPlanSteps();
setupQueries();
loadObjects();
setInterval(() => { if (!view.objectId) loadObjects(); }, 2000);  // objects created while nobody is selected
