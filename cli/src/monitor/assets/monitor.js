// Petrel monitor: the mission's nets coloured with the marking, from the monitor's event stream
// (live) or from a journal's timeline (replay). Hand-written, no dependency.
//
// Views (the address says which, so that it can be shared): the overview (`?view=overview`,
// the tree of nets, each with its state), one net (`?net=NAME`, laid out alone, its global
// places as ports, drawn at a size that reads), the map (`?view=map`) and every net in one
// drawing (`?view=all`). `&follow=1` brings the net of the latest step into view.
//
// Test hooks: every place node carries `data-name` (its DOT id, `NET.place`, `global.place`)
// and the class `marked` when it holds a token; the body carries `data-ready` (the page is
// in), `data-view` and `data-net` (what is shown), `data-step` (the next step expected, live;
// the frame's step, replay), `data-synced` and `data-time` (replay).
'use strict';

const SVGNS = 'http://www.w3.org/2000/svg';
// A label is drawn at least this many times its size in the drawing (Graphviz's 10 points
// then read as 12.5 px): a net is never shrunk below it to fit; it is panned instead.
const READABLE = 1.25;
// The most a small net is enlarged to fill the canvas.
const LARGEST = 2.2;

const M = {
  model: null, token: null, mode: 'live',
  marked: new Set(), active: new Set(), step: 0, synced: false,
  nets: new Map(), netItems: new Map(), placeIds: new Set(),
  view: 'overview', net: null, svg: null, box: null, full: null,
  nodes: [], clusters: new Map(), edges: [], svgCache: new Map(),
  places: new Map(), transitions: new Map(), treeNodes: new Map(), moved: false,
  frames: [], frameIndex: 0, playing: null, follow: false, lastNet: null,
  status: null, streamOpen: false, mapVersion: 0, mapShown: -1,
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
// The net of a node id: `NET.place`, `NET.t.transition`, `NET.done.CHILD`.
const netOf = (id) => {
  const i = id.indexOf('.');
  return i < 0 ? id : id.slice(0, i);
};
// A name that may be broken after a `/` or a `.` only, never inside a word (with `words`,
// also between the words of a snake_case name, for the narrow list of nets).
function breakable(text, words) {
  const f = document.createDocumentFragment();
  for (const part of String(text).split(words ? /(?<=[/._])/ : /(?<=[/.])/)) {
    f.append(document.createTextNode(part), document.createElement('wbr'));
  }
  return f;
}
// A link to a net's view: a click anywhere a net is named opens it (one listener for the
// whole page, so that a log row of forty transitions costs no forty listeners).
function netLink(name, text) {
  const a = el('a', { class: 'net', 'data-net': name, title: 'open net ' + name });
  a.append(breakable(text || name));
  return a;
}
document.addEventListener('click', (e) => {
  const a = e.target.closest && e.target.closest('a.net');
  if (a) { e.preventDefault(); openNet(a.dataset.net); }
});

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
  indexModel();
  buildNetList();
  setupSearch();
  setupCanvas();
  if (M.model.operator) setupOperator();
  if (!M.model.map) {
    $('tab-map').disabled = true;
    $('tab-map').title = 'this project has no map.toml (docs/monitor.md, "The map")';
  }
  for (const b of document.querySelectorAll('#tabs button')) {
    b.addEventListener('click', () => (b.dataset.view === 'net' ? openNet(M.net || M.model.nets[0].name) : show(b.dataset.view)));
  }
  M.follow = q.get('follow') === '1';
  $('follow').checked = M.follow;
  $('follow').addEventListener('change', () => { M.follow = $('follow').checked; setAddress(); if (M.follow) followLast(); });
  const net = q.get('net');
  const view = net ? 'net' : (q.get('view') || (M.model.nets.length <= 4 ? 'all' : 'overview'));
  if (net && !M.nets.has(net)) $('notice').textContent = 'no net named ' + net + ' in this project';
  // A replay's marking first: the view opens on it.
  if (M.mode === 'replay') await loadReplay(q);
  await show(M.nets.has(net) ? 'net' : (view === 'net' ? 'overview' : view), M.nets.has(net) ? net : null);
  document.body.dataset.ready = 'true';
  if (M.mode === 'live') connect();
}

// ---- The project -------------------------------------------------------------------------

function indexModel() {
  for (const g of M.model.globals) M.placeIds.add(g);
  for (const n of M.model.nets) {
    n.terminalSet = new Set(n.terminal);
    M.nets.set(n.name, n);
    for (const p of n.places) M.placeIds.add(p);
  }
}

// A net's state: inactive; ended (every marked place is one no transition of it takes);
// active (a transition has its input places marked, or a child runs: it waits for it); stuck
// (neither: it waits for a token another net must give, or for ever).
function netState(n) {
  if (!M.active.has(n.name)) return 'inactive';
  const marked = n.places.filter((p) => M.marked.has(p));
  if (marked.length && marked.every((p) => n.terminalSet.has(p))) return 'ended';
  const ready = n.transitions.some((t) => t.in.every((p) => M.marked.has(p)) && t.empty.every((p) => !M.marked.has(p)));
  if (ready || n.children.some((c) => M.active.has(c))) return 'active';
  return 'stuck';
}
const markedCount = (n) => n.places.reduce((k, p) => k + (M.marked.has(p) ? 1 : 0), 0);

function buildNetList() {
  const list = $('netlist');
  for (const n of M.model.nets) {
    // A child instance `A/B/C` shows as `C` under its parent, indented by its depth.
    const parts = n.name.split('/');
    const name = el('span', { class: 'name' });
    name.append(breakable(parts[parts.length - 1], true));
    const li = el('li', { 'data-net': n.name }, el('i', { class: 'st' }), name, el('span', { class: 'count' }));
    li.style.paddingLeft = (4 + 12 * (parts.length - 1)) + 'px';
    li.title = n.template !== n.name ? n.name + ' = ' + n.template : n.name;
    li.onclick = () => openNet(n.name);
    list.append(li);
    M.netItems.set(n.name, li);
  }
}

// ---- Search ------------------------------------------------------------------------------

function setupSearch() {
  const input = $('search');
  const results = $('results');
  const entries = [];
  for (const n of M.model.nets) {
    entries.push({ kind: 'net', text: n.name, net: n.name, node: null });
    for (const p of n.places) entries.push({ kind: 'place', text: p, net: n.name, node: p });
    for (const t of n.transitions) {
      entries.push({ kind: 'transition', text: t.id.replace('.t.', '.') + (t.event ? ' on ' + t.event : ''), net: n.name, node: t.id });
    }
  }
  for (const g of M.model.globals) {
    const users = M.model.nets.filter((n) => n.globals.includes(g));
    for (const n of users) entries.push({ kind: 'global place', text: g + ' in ' + n.name, net: n.name, node: g });
  }
  M.search = (text) => {
    const f = text.trim().toLowerCase();
    if (!f) return [];
    return entries.filter((e) => (e.text + ' ' + (e.node || '')).toLowerCase().includes(f));
  };
  input.addEventListener('input', () => {
    const found = M.search(input.value).slice(0, 60);
    results.hidden = input.value.trim() === '';
    results.replaceChildren(...found.map((e) => {
      const li = el('li', { 'data-net': e.net }, el('span', { class: 'kind' }, e.kind));
      li.append(breakable(e.text));
      li.onclick = () => { openNet(e.net, e.node); };
      return li;
    }));
    if (!found.length && !results.hidden) results.append(el('li', {}, 'nothing named so'));
  });
  input.addEventListener('keydown', (e) => {
    if (e.key === 'Escape') { input.value = ''; input.dispatchEvent(new Event('input')); input.blur(); }
    if (e.key === 'Enter') { const first = results.querySelector('li[data-net]'); if (first) first.click(); }
  });
  document.addEventListener('keydown', (e) => {
    if (e.key === '/' && document.activeElement.tagName !== 'INPUT') { e.preventDefault(); input.focus(); }
  });
}

// ---- Views ---------------------------------------------------------------------------------

function setAddress() {
  const q = new URLSearchParams(location.search);
  q.delete('net'); q.delete('view'); q.delete('follow');
  if (M.view === 'net' && M.net) q.set('net', M.net); else q.set('view', M.view);
  if (M.follow) q.set('follow', '1');
  history.replaceState(null, '', location.pathname + '?' + q.toString().replace(/%2F/g, '/'));
}

async function fetchText(url) {
  if (M.svgCache.has(url)) return M.svgCache.get(url);
  const r = await fetch(url);
  const text = await r.text();
  if (!r.ok) throw new Error(text);
  M.svgCache.set(url, text);
  return text;
}

function openNet(name, node) {
  if (!M.nets.has(name)) return;
  return show('net', name, node);
}

// Shows `view` (with `net` for a net's view; `node` to point at one of its nodes).
async function show(view, net, node) {
  const seq = (M.showSeq = (M.showSeq || 0) + 1);
  let svgText;
  try {
    if (view === 'net') svgText = await fetchText('/api/net.svg?name=' + encodeURIComponent(net));
    else if (view === 'overview') svgText = await fetchText('/api/tree.svg');
    else if (view === 'all') svgText = await fetchText('/api/nets.svg');
  } catch (e) {
    $('notice').textContent = 'cannot draw ' + (net || view) + ': ' + e.message;
    return;
  }
  if (seq !== M.showSeq) return; // a later choice won
  M.view = view;
  M.net = view === 'net' ? net : M.net;
  document.body.dataset.view = view;
  document.body.dataset.net = view === 'net' ? net : '';
  for (const b of document.querySelectorAll('#tabs button')) b.classList.toggle('on', b.dataset.view === view);
  $('tab-net').textContent = M.net ? 'net ' + M.net.split('/').pop() : 'net';
  for (const [name, li] of M.netItems) li.classList.toggle('selected', view === 'net' && name === net);
  $('selected').textContent = view === 'net' ? 'net ' + net : '';
  const canvas = $('canvas');
  canvas.className = 'drawing ' + view;
  legend(view);
  if (view === 'map') {
    M.svg = null;
    M.mapShown = -1;
    await drawMap();
  } else {
    canvas.innerHTML = svgText;
    M.svg = canvas.querySelector('svg');
    indexDrawing(view);
    M.shown = null;
    render();
    M.moved = false;
    fitView(fitOf(view), node);
  }
  setAddress();
}

// How a view fits: a net filling the canvas, readable; the overview and every net whole.
const fitOf = (view) => (view === 'net' ? 'readable' : 'all');

function legend(view) {
  const l = $('legend');
  const item = (cls, text) => [el('i', { class: cls }), text + ' '];
  const items = view === 'overview'
    ? [item('st-active', 'active'), item('st-ended', 'ended'), item('st-stuck', 'stuck'), item('st-inactive', 'inactive')]
    : view === 'map' ? [] : [item('m', 'marked'), item('f', 'just fired'), item('g', 'global place'), item('x', 'inactive net')];
  l.replaceChildren(...items.flat());
}

// The nodes of the drawing now shown: places, transitions, clusters, arcs.
function indexDrawing(view) {
  const svg = M.svg;
  const vb = svg.viewBox.baseVal;
  M.full = { x: vb.x, y: vb.y, w: vb.width, h: vb.height };
  svg.removeAttribute('width');
  svg.removeAttribute('height');
  M.nodes = [];
  M.places = new Map();
  M.transitions = new Map();
  M.clusters = new Map();
  M.edges = [];
  M.treeNodes = new Map();
  for (const g of svg.querySelectorAll('g.node')) {
    const id = g.querySelector('title').textContent;
    g.dataset.name = id;
    if (view === 'overview') {
      g.dataset.net = id;
      M.treeNodes.set(id, g);
      g.addEventListener('click', () => openNet(id));
      continue;
    }
    if (M.placeIds.has(id)) {
      g.classList.add('place');
      if (id.startsWith('global.')) g.classList.add('global');
      // In a net's view, a global place or the parent's completion place is a port.
      if (view === 'net' && netOf(id) !== M.net) g.classList.add('port');
      M.places.set(id, g);
    } else if (id.includes('.t.')) {
      g.classList.add('transition');
      M.transitions.set(id, g);
    }
    if (view === 'all') g.addEventListener('click', () => { if (!id.startsWith('global.')) openNet(netOf(id)); });
    M.nodes.push([g, id]);
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
}

function setupCanvas() {
  const canvas = $('canvas');
  canvas.addEventListener('wheel', (e) => {
    if (!M.svg) return;
    e.preventDefault();
    M.moved = true;
    zoom(e.deltaY < 0 ? 0.8 : 1.25, toSvg(e.clientX, e.clientY));
  }, { passive: false });
  let drag = null;
  canvas.addEventListener('mousedown', (e) => {
    if (!M.svg) return;
    drag = { x: e.clientX, y: e.clientY, box: { ...M.box } };
    M.moved = true;
    canvas.classList.add('dragging');
  });
  window.addEventListener('mouseup', () => { drag = null; canvas.classList.remove('dragging'); });
  window.addEventListener('mousemove', (e) => {
    if (!drag) return;
    const s = scale();
    setBox({ ...drag.box, x: drag.box.x - (e.clientX - drag.x) / s, y: drag.box.y - (e.clientY - drag.y) / s });
  });
  $('fit').onclick = () => { M.moved = false; if (M.view === 'map') drawMap(true); else fitView(fitOf(M.view)); };
  $('zoomin').onclick = () => { M.moved = true; zoom(0.8); };
  $('zoomout').onclick = () => { M.moved = true; zoom(1.25); };
  // A canvas that changes size (the window, the replay's bar) fits its view again.
  let resized = null;
  let size = '';
  new ResizeObserver(() => {
    const r = canvas.getBoundingClientRect();
    const now = Math.round(r.width) + 'x' + Math.round(r.height);
    if (now === size) return;
    size = now;
    clearTimeout(resized);
    resized = setTimeout(() => {
      if (M.view === 'map') drawMap(true);
      else if (!M.moved) fitView(fitOf(M.view));
    }, 100);
  }).observe(canvas);
}

function setBox(b) {
  M.box = b;
  if (M.svg) M.svg.setAttribute('viewBox', `${b.x} ${b.y} ${b.w} ${b.h}`);
}

// Screen pixels per unit of the drawing.
function scale() {
  const r = $('canvas').getBoundingClientRect();
  return Math.min(r.width / M.box.w, r.height / M.box.h);
}

function toSvg(cx, cy) {
  const r = $('canvas').getBoundingClientRect();
  const s = scale();
  // The view box is centred in the canvas (preserveAspectRatio meet).
  const ox = (r.width - M.box.w * s) / 2, oy = (r.height - M.box.h * s) / 2;
  return { x: M.box.x + (cx - r.left - ox) / s, y: M.box.y + (cy - r.top - oy) / s };
}

function zoom(f, at) {
  if (!M.svg) return;
  const b = M.box;
  const c = at || { x: b.x + b.w / 2, y: b.y + b.h / 2 };
  setBox({ x: c.x - (c.x - b.x) * f, y: c.y - (c.y - b.y) * f, w: b.w * f, h: b.h * f });
}

// Fits the drawing to the canvas: `all` whole, whatever its size; `readable` (a net, the
// overview) filling the canvas but never smaller than READABLE, then centred on `node`, or
// on the marked places, or shown from its start.
function fitView(how, node) {
  if (!M.svg || !M.full) return;
  const r = $('canvas').getBoundingClientRect();
  if (!r.width || !r.height) return;
  const f = M.full;
  let s = Math.min(r.width / f.w, r.height / f.h);
  if (how === 'readable') s = Math.max(READABLE, Math.min(LARGEST, s));
  const w = r.width / s, h = r.height / s;
  let cx = f.x + f.w / 2, cy = f.y + f.h / 2;
  if (w < f.w || h < f.h) {
    const target = node && nodeBox(node) || markedBox();
    if (target) { cx = target.x + target.w / 2; cy = target.y + target.h / 2; } else { cx = f.x + w / 2; cy = f.y + h / 2; }
    // Keep the drawing in the canvas on each axis it overflows.
    if (w < f.w) cx = Math.max(f.x + w / 2, Math.min(f.x + f.w - w / 2, cx));
    if (h < f.h) cy = Math.max(f.y + h / 2, Math.min(f.y + f.h - h / 2, cy));
  }
  setBox({ x: cx - w / 2, y: cy - h / 2, w, h });
  for (const g of M.svg.querySelectorAll('g.found')) g.classList.remove('found');
  if (node) {
    const g = [...M.nodes].find(([, id]) => id === node);
    if (g) g[0].classList.add('found');
  }
}

// The box of a node, in the drawing's units.
function nodeBox(id) {
  const g = M.nodes.find(([, n]) => n === id);
  if (!g) return null;
  const b = g[0].getBBox();
  return { x: b.x, y: b.y, w: b.width, h: b.height };
}

function markedBox() {
  let box = null;
  for (const [id, g] of M.places) {
    if (!M.marked.has(id)) continue;
    const b = g.getBBox();
    box = box ? { x: Math.min(box.x, b.x), y: Math.min(box.y, b.y), x2: Math.max(box.x2, b.x + b.width), y2: Math.max(box.y2, b.y + b.height) }
      : { x: b.x, y: b.y, x2: b.x + b.width, y2: b.y + b.height };
  }
  return box && { x: box.x, y: box.y, w: box.x2 - box.x, h: box.y2 - box.y };
}

// ---- The map -------------------------------------------------------------------------------

// Draws the map at the canvas's size (live: as it is now; replay: at the slider's time).
// `again`: even if the drawing did not change (a new size).
async function drawMap(again) {
  if (M.view !== 'map' || !M.model.map) {
    if (M.view === 'map') $('canvas').replaceChildren(el('div', { class: 'empty' }, 'This project has no map: its map.toml says what to draw and where the positions come from (docs/monitor.md, "The map").'));
    return;
  }
  const key = M.mode === 'replay' ? 'r' + M.frameIndex : 'v' + M.mapVersion;
  if (!again && key === M.mapShown) return;
  if (M.mapBusy) { M.mapAgain = true; return; }
  M.mapBusy = true;
  try {
    const r = $('canvas').getBoundingClientRect();
    let url = `/api/map.svg?w=${Math.round(r.width)}&h=${Math.round(r.height)}`;
    if (M.mode === 'replay' && M.frames.length) url += '&t=' + encodeURIComponent(M.frames[M.frameIndex].time);
    const res = await fetch(url);
    const text = await res.text();
    if (M.view === 'map') {
      $('canvas').innerHTML = res.ok ? text : '';
      M.mapShown = key;
      document.body.dataset.map = key;
    }
  } finally {
    M.mapBusy = false;
    if (M.mapAgain) { M.mapAgain = false; drawMap(); }
  }
}

// ---- The marking -------------------------------------------------------------------------

// Draws the marking on the view shown, the nets' states and counts in the list (and on the
// overview), and the header.
function render() {
  if (M.view === 'overview') renderOverview();
  else if (M.view === 'net' || M.view === 'all') renderNets();
  for (const n of M.model.nets) {
    const li = M.netItems.get(n.name);
    const st = netState(n);
    const c = markedCount(n);
    if (li.dataset.state !== st) {
      li.dataset.state = st;
      li.className = li.className.replace(/\bst-\w+/g, '').trim() + ' st-' + st;
      li.querySelector('i.st').className = 'st st-' + st;
      li.title = n.name + ': ' + st;
    }
    const text = c ? String(c) : '';
    const count = li.querySelector('.count');
    if (count.textContent !== text) count.textContent = text;
    li.classList.toggle('last', n.name === M.lastNet);
  }
  document.body.dataset.step = String(M.step);
  document.body.dataset.synced = String(M.synced);
}

// Only what changed since the drawing was last coloured: the places whose token came or
// went, and, when a net was activated or deactivated, the nets' nodes, frames and arcs.
function renderNets() {
  const shown = M.shown;
  const changed = shown ? [...M.marked].filter((p) => !shown.marked.has(p)).concat([...shown.marked].filter((p) => !M.marked.has(p)))
    : [...M.places.keys()];
  for (const id of changed) {
    const g = M.places.get(id);
    if (g) g.classList.toggle('marked', M.marked.has(id));
  }
  const activity = !shown || shown.active.size !== M.active.size || [...M.active].some((n) => !shown.active.has(n));
  if (activity) {
    const on = (net) => net === 'global' || M.active.has(net);
    for (const [g, id] of M.nodes) if (!g.classList.contains('port')) g.classList.toggle('inactive', !on(netOf(id)));
    for (const [net, g] of M.clusters) g.classList.toggle('inactive', !on(net));
    for (const [g, a, b] of M.edges) g.classList.toggle('inactive', !(on(a) && on(b)));
  }
  M.shown = { marked: new Set(M.marked), active: new Set(M.active) };
}

// The boxes whose state, count or "last" changed (writing the same again would still cost a
// style pass of the drawing).
function renderOverview() {
  for (const [name, g] of M.treeNodes) {
    const n = M.nets.get(name);
    if (!n) continue;
    const st = netState(n);
    if (g.dataset.state !== st) {
      for (const s of ['active', 'ended', 'stuck', 'inactive']) g.classList.toggle('st-' + s, s === st);
      g.dataset.state = st;
    }
    const last = name === M.lastNet;
    if (g.classList.contains('last') !== last) g.classList.toggle('last', last);
    badge(g, markedCount(n));
  }
}

// A net's count of marked places, at the top right of its box.
function badge(g, count) {
  if (g._badge && g._badge.count === count) return;
  let b = g._badge;
  if (!b) {
    const box = g.getBBox();
    const rect = document.createElementNS(SVGNS, 'rect');
    const text = document.createElementNS(SVGNS, 'text');
    rect.setAttribute('class', 'badge');
    rect.setAttribute('x', box.x + box.width - 9);
    rect.setAttribute('y', box.y - 7);
    rect.setAttribute('width', 18);
    rect.setAttribute('height', 14);
    rect.setAttribute('rx', 7);
    text.setAttribute('class', 'badge');
    text.setAttribute('x', box.x + box.width);
    text.setAttribute('y', box.y + 4);
    text.setAttribute('text-anchor', 'middle');
    text.setAttribute('font-size', '10');
    g.append(rect, text);
    b = g._badge = { rect, text };
  }
  b.rect.setAttribute('visibility', count ? 'visible' : 'hidden');
  b.text.textContent = count ? String(count) : '';
  b.count = count;
}

// Lights the transitions that fired for a second and a half (a class, no animation: nothing
// to restart, so no layout is forced here).
function flash(fired) {
  for (const id of fired || []) {
    const g = M.transitions && M.transitions.get(id);
    if (!g) continue;
    g.classList.add('fired');
    clearTimeout(g._flash);
    g._flash = setTimeout(() => g.classList.remove('fired'), 1500);
  }
}

// The net of the latest step that fired a transition: the follow mode shows it.
function noteLast(steps) {
  for (let i = steps.length - 1; i >= 0; i--) {
    const f = steps[i].fired || [];
    if (f.length) { M.lastNet = netOf(f[f.length - 1]); return; }
  }
}

function followLast() {
  if (!M.follow || !M.lastNet || M.view === 'map') return;
  if (M.view === 'net' && M.net === M.lastNet) return;
  // At most a net a second, the latest: a busy mission does not flicker.
  const now = performance.now();
  const wait = Math.max(0, (M.followedAt || 0) + 700 - now);
  clearTimeout(M.followTimer);
  M.followTimer = setTimeout(() => {
    M.followedAt = performance.now();
    if (M.follow && M.lastNet && !(M.view === 'net' && M.net === M.lastNet)) openNet(M.lastNet);
  }, wait);
}

function header(time) {
  $('step').textContent = M.step;
  $('time').textContent = time == null ? '-' : Number(time).toFixed(3);
}

function logRow(s, prepend) {
  const ev = s.event ? s.event + (s.params && s.params.length ? '(' + s.params.join(', ') + ')' : '') : '(start)';
  const fired = el('td', {});
  (s.fired || []).forEach((t, i) => {
    if (i) fired.append(' ');
    fired.append(netLink(netOf(t), t.replace('.t.', '.')));
  });
  const actions = el('td', {});
  const acts = s.actions || [];
  acts.forEach((a, i) => {
    // `activate NET`, `deactivate NET`: the net is a link.
    const m = /^(activate|deactivate) ([^\s(]+)(.*)$/.exec(a);
    if (m && M.nets.has(m[2])) actions.append(m[1] + ' ', netLink(m[2]), m[3]);
    else actions.append(breakable(a));
    if (i + 1 < acts.length) actions.append('; ');
  });
  const tr = el('tr', { 'data-step': s.step },
    el('td', {}, Number(s.time).toFixed(3)),
    el('td', {}, s.step),
    el('td', {}, breakable(ev)),
    el('td', { class: 'cat-' + (s.category || '') }, s.category || ''),
    fired,
    actions);
  const body = $('log').tBodies[0];
  if (prepend === true) body.prepend(tr);
  else if (prepend === false) body.append(tr);
  while (prepend && body.rows.length > 300) body.deleteRow(body.rows.length - 1);
  return tr;
}

// ---- Live ----------------------------------------------------------------------------------

// What the header says of the connection: the monitor's stream, and whether a player is heard
// (never "connected" on the stream alone: a monitor whose vehicle is gone says so).
function connState() {
  const c = $('conn');
  let state, text, cls;
  const player = M.status && M.status.player;
  if (!M.streamOpen) {
    [state, text, cls] = M.streamFailed ? ['monitor-lost', 'monitor unreachable, retrying', 'bad'] : ['connecting', 'connecting', 'wait'];
  } else if (player === 'alive') {
    [state, text, cls] = ['player-alive', 'player alive', 'ok'];
  } else if (player === 'silent') {
    [state, text, cls] = ['player-silent', 'player silent (no heartbeat)', 'bad'];
  } else {
    [state, text, cls] = ['no-player', 'monitor up, no player heard', 'wait'];
  }
  c.textContent = text;
  c.className = 'pill ' + cls;
  c.dataset.state = state;
}

function connect() {
  const es = new EventSource('/api/events');
  es.onopen = () => { M.streamOpen = true; M.streamFailed = false; connState(); };
  es.onerror = () => { M.streamOpen = false; M.streamFailed = true; M.status = null; connState(); };
  es.onmessage = (e) => {
    let m;
    try { m = JSON.parse(e.data); } catch (_) { return; }
    if (m.type === 'snapshot') onSnapshot(m);
    else if (m.type === 'step') onStep(m);
    else if (m.type === 'status') onStatus(m);
    else if (m.type === 'map') { M.mapVersion = m.version; drawMap(); }
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
    noteLast(m.log);
  }
  header(m.time);
  render();
  // The first marking: a net's view centres on it (unless the user moved it).
  if (M.view === 'net' && !M.moved) fitView('readable');
  followLast();
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
  noteLast(steps);
  header(last.time);
  render();
  // Only the latest steps are worth a row and a flash: a burst scrolls by anyway.
  const rows = document.createDocumentFragment();
  for (const s of steps.slice(-50)) { flash(s.fired); rows.prepend(logRow(s)); }
  const body = $('log').tBodies[0];
  body.prepend(rows);
  while (body.rows.length > 300) body.deleteRow(body.rows.length - 1);
  if (!$('notice').textContent.startsWith('this page')) $('notice').textContent = '';
  followLast();
  requestAnimationFrame(() => {
    const at = performance.timeOrigin + performance.now();
    for (const s of steps) M.shownAt[s.step] = at;
  });
}

function onStatus(m) {
  M.status = m;
  connState();
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
    out.dataset.verdict = 'waiting';
    out.textContent = 'sending ' + text + '...';
    const t0 = performance.now();
    try {
      const r = await fetch('/api/send', {
        method: 'POST',
        headers: { 'Content-Type': 'application/json', 'X-Petrel-Token': M.token || '' },
        body: JSON.stringify({ event: text }),
      });
      const j = await r.json();
      out.className = r.ok ? 'ok' : 'bad';
      // The player's verdict when it gave one (taken, or refused with its reason), else why
      // the monitor did not send.
      out.dataset.verdict = r.ok ? 'taken' : (j.verdict ? 'refused' : 'error');
      out.textContent = j.verdict ? `${j.event}: ${j.verdict}` : (j.error || r.status);
    } catch (e) {
      out.className = 'bad';
      out.dataset.verdict = 'error';
      out.textContent = String(e);
    }
    out.dataset.ms = String(Math.round(performance.now() - t0));
  });
}

// ---- Replay --------------------------------------------------------------------------------

async function loadReplay(q) {
  const t = await getJson('/api/replay');
  M.frames = t.frames;
  const c = $('conn');
  c.textContent = 'journal replay';
  c.className = 'pill info';
  c.dataset.state = 'replay';
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
  M.frames.forEach((f, i) => {
    const tr = logRow(f, false);
    tr.addEventListener('click', (e) => { if (!e.target.closest('a')) { pause(); showFrame(i); } });
  });
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
  for (let k = i; k >= 0; k--) {
    const fired = M.frames[k].fired || [];
    if (fired.length) { M.lastNet = netOf(fired[fired.length - 1]); break; }
  }
  header(f.time);
  render();
  flash(f.fired);
  // The log follows: the frame's row highlighted and scrolled into the log's view.
  const rows = $('log').tBodies[0].rows;
  for (const r of rows) r.classList.remove('current');
  const row = rows[i];
  if (row) {
    row.classList.add('current');
    const wrap = $('logwrap');
    const top = row.offsetTop;
    if (top < wrap.scrollTop || top + row.offsetHeight > wrap.scrollTop + wrap.clientHeight) {
      wrap.scrollTop = Math.max(0, top - wrap.clientHeight / 3);
    }
  }
  followLast();
  drawMap();
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
