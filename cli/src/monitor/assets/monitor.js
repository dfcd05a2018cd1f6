// Petrel monitor: colours Graphviz's drawing of the nets with the marking, from the monitor's
// event stream (live) or from a journal's timeline (replay). Hand-written, no dependency.
//
// Test hooks: every place node carries `data-name` (its DOT id, `NET.place`, `global.place`)
// and the class `marked` when it holds a token; the body carries `data-ready` (the drawing is
// in), `data-step` (the next step expected, live; the frame's step, replay) and `data-synced`.
'use strict';

const M = {
  model: null, token: null, mode: 'live',
  marked: new Set(), active: new Set(), step: 0, synced: false,
  places: new Map(), transitions: new Map(), clusters: new Map(), edges: [], treeNodes: new Map(),
  netItems: new Map(), netNodes: new Map(), shown: null, selected: null, view: null, full: null, svg: null,
  frames: [], frameIndex: 0, playing: null,
};
window.petrelMonitor = M;

const $ = (id) => document.getElementById(id);
const el = (tag, attrs, ...children) => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === 'class') e.className = v; else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  return e;
};
const netOf = (id) => {
  const i = id.indexOf('.');
  return i < 0 ? id : id.slice(0, i);
};

async function getJson(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(url + ': ' + r.status);
  return r.json();
}

// The operator's token comes in the address's fragment (`/#token=...`: a fragment is never
// sent to a server nor put in a Referer), or in the query as older addresses had it. It is
// kept for this tab only (sessionStorage), sent in a header, and taken out of the address so
// that it does not stay in the browser's history.
function takeToken() {
  const key = 'petrel-token';
  const hash = new URLSearchParams(location.hash.slice(1));
  const query = new URLSearchParams(location.search);
  const given = hash.get('token') || query.get('token');
  if (given) {
    sessionStorage.setItem(key, given);
    hash.delete('token');
    query.delete('token');
    const q = query.toString(), h = hash.toString();
    history.replaceState(null, '', location.pathname + (q ? '?' + q : '') + (h ? '#' + h : ''));
  }
  M.token = sessionStorage.getItem(key);
}

// What the page's Content Security Policy blocked (a test hook: the policy must not break it).
M.blocked = [];
document.addEventListener('securitypolicyviolation', (e) => M.blocked.push(e.violatedDirective + ' ' + e.blockedURI));

async function main() {
  takeToken();
  window.addEventListener('hashchange', takeToken);
  const q = new URLSearchParams(location.search);
  M.model = await getJson('/api/model');
  M.mode = M.model.mode;
  document.title = 'Petrel monitor: ' + M.model.project;
  $('project').textContent = M.model.project;
  $('mode').textContent = M.mode === 'live' ? 'vehicle ' + M.model.vehicle : 'replay of a journal';
  await loadDrawing();
  buildNetList();
  if (M.model.operator) setupOperator();
  document.body.dataset.ready = 'true';
  if (M.mode === 'live') connect();
  else await loadReplay(q);
}

// ---- The drawing ---------------------------------------------------------------------------

async function loadDrawing() {
  const [nets, tree] = await Promise.all([
    fetch('/api/nets.svg').then((r) => r.text()),
    fetch('/api/tree.svg').then((r) => r.text()),
  ]);
  $('canvas').innerHTML = nets;
  $('tree').innerHTML = tree;
  const placeIds = new Set(M.model.globals);
  for (const n of M.model.nets) for (const p of n.places) placeIds.add(p);
  const svg = $('canvas').querySelector('svg');
  M.svg = svg;
  for (const g of svg.querySelectorAll('g.node')) {
    const id = g.querySelector('title').textContent;
    g.dataset.name = id;
    if (placeIds.has(id)) {
      g.classList.add('place');
      if (id.startsWith('global.')) g.classList.add('global');
      M.places.set(id, g);
    } else if (id.includes('.t.')) {
      g.classList.add('transition');
      M.transitions.set(id, g);
    }
    g.addEventListener('click', () => selectNet(netOf(id), false));
    if (!id.startsWith('global.')) {
      const net = netOf(id);
      if (!M.netNodes.has(net)) M.netNodes.set(net, []);
      M.netNodes.get(net).push(g);
    }
  }
  for (const g of svg.querySelectorAll('g.cluster')) {
    const t = g.querySelector('title').textContent;
    if (t.startsWith('cluster_')) {
      g.dataset.net = t.slice(8);
      M.clusters.set(t.slice(8), g);
    }
  }
  for (const g of svg.querySelectorAll('g.edge')) {
    const [a, b] = g.querySelector('title').textContent.split('->');
    M.edges.push([g, netOf(a), netOf(b || a)]);
  }
  for (const g of $('tree').querySelectorAll('g.node')) {
    const name = g.querySelector('title').textContent;
    g.dataset.net = name;
    M.treeNodes.set(name, g);
    g.addEventListener('click', () => selectNet(name, true));
  }
  // Zoom and pan on the viewBox: the drawing is laid out once, only the view moves.
  const vb = svg.viewBox.baseVal;
  M.full = { x: vb.x, y: vb.y, w: vb.width, h: vb.height };
  svg.removeAttribute('width');
  svg.removeAttribute('height');
  setView(M.full);
  const canvas = $('canvas');
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    const p = toSvg(e.clientX, e.clientY);
    zoom(e.deltaY < 0 ? 0.8 : 1.25, p);
  }, { passive: false });
  let drag = null;
  canvas.addEventListener('mousedown', (e) => {
    drag = { x: e.clientX, y: e.clientY, view: { ...M.view } };
    canvas.classList.add('dragging');
  });
  window.addEventListener('mouseup', () => { drag = null; canvas.classList.remove('dragging'); });
  window.addEventListener('mousemove', (e) => {
    if (!drag) return;
    const r = canvas.getBoundingClientRect();
    const s = Math.max(drag.view.w / r.width, drag.view.h / r.height);
    setView({ ...drag.view, x: drag.view.x - (e.clientX - drag.x) * s, y: drag.view.y - (e.clientY - drag.y) * s });
  });
  $('fit').onclick = () => { setView(M.full); selectNet(null); };
  $('zoomin').onclick = () => zoom(0.8);
  $('zoomout').onclick = () => zoom(1.25);
}

function setView(v) {
  M.view = v;
  M.svg.setAttribute('viewBox', `${v.x} ${v.y} ${v.w} ${v.h}`);
}

function toSvg(cx, cy) {
  const pt = M.svg.createSVGPoint();
  pt.x = cx; pt.y = cy;
  const m = M.svg.getScreenCTM();
  return m ? pt.matrixTransform(m.inverse()) : { x: M.view.x + M.view.w / 2, y: M.view.y + M.view.h / 2 };
}

function zoom(f, at) {
  const v = M.view;
  const c = at || { x: v.x + v.w / 2, y: v.y + v.h / 2 };
  setView({ x: c.x - (c.x - v.x) * f, y: c.y - (c.y - v.y) * f, w: v.w * f, h: v.h * f });
}

function buildNetList() {
  const list = $('netlist');
  for (const n of M.model.nets) {
    // A child instance `A/B/C` shows as `C` under its parent, indented by its depth.
    const parts = n.name.split('/');
    const li = el('li', { 'data-net': n.name }, (parts.length > 1 ? '\u2514 ' : '') + parts[parts.length - 1], el('span', { class: 'count' }));
    li.style.paddingLeft = (4 + 12 * (parts.length - 1)) + 'px';
    li.title = n.template !== n.name ? n.name + ' = ' + n.template : n.name;
    li.onclick = () => selectNet(n.name, true);
    list.append(li);
    M.netItems.set(n.name, li);
  }
  $('filter').addEventListener('input', (e) => {
    const f = e.target.value.toLowerCase();
    for (const [name, li] of M.netItems) li.hidden = f !== '' && !name.toLowerCase().includes(f);
  });
}

// Selects a net (highlights it, and with `zoomTo` fits the view on its cluster).
function selectNet(name, zoomTo) {
  for (const g of M.clusters.values()) g.classList.remove('selected');
  for (const li of M.netItems.values()) li.classList.remove('selected');
  M.selected = name;
  $('selected').textContent = name ? 'net ' + name : '';
  if (!name) return;
  const g = M.clusters.get(name);
  if (g) g.classList.add('selected');
  const li = M.netItems.get(name);
  if (li) li.classList.add('selected');
  if (g && zoomTo) {
    const r = g.getBoundingClientRect();
    const a = toSvg(r.left, r.top), b = toSvg(r.right, r.bottom);
    const pad = 20;
    setView({ x: a.x - pad, y: a.y - pad, w: b.x - a.x + 2 * pad, h: b.y - a.y + 2 * pad });
  }
}

// ---- The marking ---------------------------------------------------------------------------

// Redraws what changed since the last call: the places whose token came or went, the nets
// activated or deactivated (their nodes, arcs and cluster), and their counts in the list.
function render() {
  const shown = M.shown || { marked: new Set(), active: new Set(), first: true };
  const touchedNets = new Set();
  const changed = shown.first ? [...M.places.keys()]
    : [...M.marked].filter((p) => !shown.marked.has(p)).concat([...shown.marked].filter((p) => !M.marked.has(p)));
  for (const id of changed) {
    const g = M.places.get(id);
    if (g) g.classList.toggle('marked', M.marked.has(id));
    touchedNets.add(netOf(id));
  }
  const nets = shown.first ? M.model.nets.map((n) => n.name)
    : [...M.active].filter((n) => !shown.active.has(n)).concat([...shown.active].filter((n) => !M.active.has(n)));
  for (const net of nets) {
    const on = M.active.has(net);
    touchedNets.add(net);
    for (const g of M.netNodes.get(net) || []) g.classList.toggle('inactive', !on);
    const c = M.clusters.get(net);
    if (c) c.classList.toggle('inactive', !on);
    const t = M.treeNodes.get(net);
    if (t) t.classList.toggle('active', on);
    const li = M.netItems.get(net);
    if (li) li.classList.toggle('inactive', !on);
  }
  if (nets.length || shown.first) {
    const activeNet = (net) => net === 'global' || M.active.has(net);
    for (const [g, a, b] of M.edges) g.classList.toggle('inactive', !(activeNet(a) && activeNet(b)));
  }
  for (const net of touchedNets) {
    const li = M.netItems.get(net);
    if (!li) continue;
    let n = 0;
    for (const p of M.marked) if (netOf(p) === net) n++;
    li.querySelector('.count').textContent = n ? n : '';
  }
  M.shown = { marked: new Set(M.marked), active: new Set(M.active), first: false };
  document.body.dataset.step = String(M.step);
  document.body.dataset.synced = String(M.synced);
}

function flash(fired) {
  for (const id of fired || []) {
    const g = M.transitions.get(id);
    if (!g) continue;
    g.classList.remove('fired');
    void g.getBoundingClientRect();
    g.classList.add('fired');
    clearTimeout(g._flash);
    g._flash = setTimeout(() => g.classList.remove('fired'), 1500);
  }
}

function header(time) {
  $('step').textContent = M.step;
  $('time').textContent = time == null ? '-' : Number(time).toFixed(3);
}

function logRow(s, prepend) {
  const ev = s.event ? s.event + (s.params && s.params.length ? '(' + s.params.join(', ') + ')' : '') : '(start)';
  const tr = el('tr', { 'data-step': s.step },
    el('td', {}, Number(s.time).toFixed(3)),
    el('td', {}, s.step),
    el('td', {}, ev),
    el('td', { class: 'cat-' + (s.category || '') }, s.category || ''),
    el('td', {}, (s.fired || []).map((t) => t.replace('.t.', '.')).join(' ')),
    el('td', {}, (s.actions || []).join('; ')));
  const body = $('log').tBodies[0];
  if (prepend) body.prepend(tr); else body.append(tr);
  while (prepend && body.rows.length > 300) body.deleteRow(body.rows.length - 1);
  return tr;
}

// ---- Live ----------------------------------------------------------------------------------

function connect() {
  const es = new EventSource('/api/events');
  es.onopen = () => { $('conn').textContent = 'connected'; $('conn').className = 'ok'; };
  es.onerror = () => { $('conn').textContent = 'disconnected, retrying'; $('conn').className = 'bad'; };
  es.onmessage = (e) => {
    let m;
    try { m = JSON.parse(e.data); } catch (_) { return; }
    if (m.type === 'snapshot') onSnapshot(m);
    else if (m.type === 'step') onStep(m);
    else if (m.type === 'status') onStatus(m);
  };
}

function onSnapshot(m) {
  M.pending = [];
  M.marked = new Set(m.marked);
  M.active = new Set(m.active);
  M.step = m.step;
  M.synced = m.synced;
  $('over').hidden = !m.over;
  let notice = m.notice || '';
  if (m.skipped) notice = `this page fell ${m.skipped} messages behind: it skipped to the latest marking`;
  $('notice').textContent = notice;
  if (m.log && m.log.length) {
    $('log').tBodies[0].replaceChildren();
    for (const s of m.log) logRow(s, true);
  }
  header(m.time);
  render();
}

// Steps change the state at once and the drawing once per frame: a burst of steps costs one
// redraw, not one each. `M.shownAt[step]` is when a step was first on screen (the benchmark
// of the time from a step to its display reads it).
M.pending = [];
M.shownAt = {};
M.arrivedAt = {};
function onStep(s) {
  if (s.step < M.step) return;
  M.arrivedAt[s.step] = performance.timeOrigin + performance.now();
  for (const p of s.unmarked) M.marked.delete(p);
  for (const p of s.marked) M.marked.add(p);
  for (const n of s.deactivated) M.active.delete(n);
  for (const n of s.activated) M.active.add(n);
  M.step = s.step + 1;
  M.synced = true;
  if (s.category === 'catastrophic') $('over').hidden = false;
  M.pending.push(s);
  // A hidden tab draws no frames: keep the latest steps only (the state has them all).
  if (M.pending.length > 1000) M.pending.splice(0, M.pending.length - 1000);
  if (!M.frame) M.frame = requestAnimationFrame(drawPending);
}

function drawPending() {
  M.frame = 0;
  const steps = M.pending;
  M.pending = [];
  if (!steps.length) return;
  const last = steps[steps.length - 1];
  header(last.time);
  render();
  // Only the latest steps are worth a row and a flash: a burst scrolls by anyway.
  for (const s of steps.slice(-50)) { flash(s.fired); logRow(s, true); }
  if (!$('notice').textContent.startsWith('this page')) $('notice').textContent = '';
  requestAnimationFrame(() => {
    const at = performance.timeOrigin + performance.now();
    for (const s of steps) M.shownAt[s.step] = at;
  });
}

function onStatus(m) {
  const st = m.status || {};
  const rows = [['player', m.player]];
  for (const [k, v] of Object.entries(st.stats || {})) rows.push([k, v]);
  if (st.recorder) rows.push(['flight recorder', st.recorder.state + (st.recorder.reason ? ': ' + st.recorder.reason : '')]);
  $('counters').replaceChildren(...rows.map(([k, v]) => el('tr', {}, el('td', {}, k), el('td', { class: String(v) }, v))));
  $('programs').replaceChildren(...Object.entries(m.programs || {}).map(([p, v]) =>
    el('tr', { 'data-program': p }, el('td', {}, p), el('td', { class: v }, v))));
  if (st.over) $('over').hidden = false;
  if (m.bridge) {
    const b = m.bridge;
    $('bridgebox').hidden = false;
    $('bridge').textContent = `on ${b.interface}: bus ${b.bus_state}, ${b.frames} frames, ${b.events_sent} events sent, ${b.commands} commands (${b.commands_failed} failed)`;
    $('signals').replaceChildren(...(m.signals || []).map(([n, v, t]) =>
      el('tr', {}, el('td', {}, n), el('td', {}, v), el('td', {}, Number(t).toFixed(3) + ' s'))));
  }
}

// ---- Operator ------------------------------------------------------------------------------

function setupOperator() {
  $('operator').hidden = false;
  const dl = $('eventnames');
  for (const e of M.model.events) if (!e.internal) dl.append(el('option', { value: e.params.length ? e.name + '(' : e.name }));
  $('sendform').addEventListener('submit', async (ev) => {
    ev.preventDefault();
    const text = $('sendtext').value.trim();
    const out = $('sendresult');
    out.className = '';
    out.textContent = 'sending ' + text + '...';
    try {
      const r = await fetch('/api/send', {
        method: 'POST',
        headers: { 'Content-Type': 'application/json', 'X-Petrel-Token': M.token || '' },
        body: JSON.stringify({ event: text }),
      });
      const j = await r.json();
      out.className = r.ok ? 'ok' : 'bad';
      out.textContent = r.ok ? `${j.event}: ${j.verdict}` : (j.error || j.verdict || r.status);
    } catch (e) {
      out.className = 'bad';
      out.textContent = String(e);
    }
  });
}

// ---- Replay --------------------------------------------------------------------------------

async function loadReplay(q) {
  const t = await getJson('/api/replay');
  M.frames = t.frames;
  $('conn').textContent = 'journal';
  $('conn').className = 'ok';
  $('replaybar').hidden = false;
  if (t.alarms.length) {
    $('alarms').hidden = false;
    $('alarmlist').replaceChildren(...t.alarms.map((a) =>
      el('li', { class: 'alarm' }, (a.time == null ? '' : Number(a.time).toFixed(3) + ' s: ') + a.text)));
  }
  if (t.notes.length) {
    $('notes').hidden = false;
    $('notelist').replaceChildren(...t.notes.map((n) => el('li', {}, Number(n.time).toFixed(3) + ' s: ' + n.text)));
  }
  const body = $('log').tBodies[0];
  body.replaceChildren();
  for (const f of M.frames) logRow(f, false).onclick = () => showFrame(M.frames.indexOf(f));
  const slider = $('slider');
  const first = M.frames.length ? M.frames[0].time : 0;
  const last = M.frames.length ? M.frames[M.frames.length - 1].time : 0;
  slider.min = first;
  slider.max = Math.max(last, first + 1e-6);
  slider.addEventListener('input', () => { pause(); showTime(Number(slider.value)); });
  $('prev').onclick = () => { pause(); showFrame(M.frameIndex - 1); };
  $('next').onclick = () => { pause(); showFrame(M.frameIndex + 1); };
  $('play').onclick = () => (M.playing ? pause() : play());
  if (q.has('t')) showTime(Number(q.get('t')));
  else if (q.has('step')) showFrame(Number(q.get('step')));
  else showFrame(0);
}

// The frame in force at time `t`: the last one recorded at or before it.
function showTime(t) {
  let i = 0;
  while (i + 1 < M.frames.length && M.frames[i + 1].time <= t) i++;
  showFrame(i, t);
}

function showFrame(i, t) {
  if (!M.frames.length) return;
  i = Math.max(0, Math.min(M.frames.length - 1, i));
  const f = M.frames[i];
  M.frameIndex = i;
  M.marked = new Set(f.marked);
  M.active = new Set(f.active);
  M.step = f.step;
  M.synced = true;
  const time = t == null ? f.time : t;
  $('slider').value = time;
  $('slidertime').textContent = Number(time).toFixed(3) + ' s, step ' + f.step + ' of ' + M.frames[M.frames.length - 1].step;
  document.body.dataset.time = String(time);
  header(f.time);
  render();
  flash(f.fired);
  for (const r of $('log').tBodies[0].rows) r.classList.toggle('current', r.rowIndex - 1 === i);
}

function play() {
  $('play').innerHTML = '&#10074;&#10074;';
  M.playing = setInterval(() => {
    if (M.frameIndex + 1 >= M.frames.length) return pause();
    showFrame(M.frameIndex + 1);
  }, 700);
}

function pause() {
  clearInterval(M.playing);
  M.playing = null;
  $('play').innerHTML = '&#9654;';
}

main().catch((e) => {
  $('notice').textContent = 'the monitor could not start: ' + e;
  document.body.dataset.error = String(e);
});
