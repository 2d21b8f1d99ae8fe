// Subgoal studio: draw ordered subgoals on a map, save subgoal files, try them.
// The server owns every rule (it checks each edit with the package's subgoal
// loader); this page only draws, edits and shows what the server says.
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";
const VIEW = 520;          // map size in SVG units (px)
const DRAG_START = 4;     // px of pointer travel before a press becomes a drag

const $ = (id) => document.getElementById(id);

const S = {
  domains: {},            // name -> {name, title, maps, limits, recipe}
  domain: null,
  map: "",
  geometry: null,
  docs: {},               // domain -> {file, patterns: [{name, subgoals, partial, edges}], current}
  selected: null,         // index of the selected subgoal of the current pattern
  drag: null,
  validateSeq: 0,
  validateTimer: null,
  job: null,              // the running "Try it": {id, domain, pattern}
  results: {},            // domain/pattern -> {result, signature}
  newComponents: null,    // form: the components a new box subgoal covers
};

class ApiError extends Error {
  constructor(message, status) { super(message); this.status = status; }
}

// The studio's per-launch token, from the address it printed (?token=...): every request carries it.
const TOKEN = new URLSearchParams(location.search).get("token");

// The page's address with ?file=NAME (or none), keeping the token.
function pageUrl(file) {
  const query = new URLSearchParams();
  if (TOKEN) query.set("token", TOKEN);
  if (file) query.set("file", file);
  const text = query.toString();
  return text ? `${location.pathname}?${text}` : location.pathname;
}

async function api(method, url, body) {
  const options = { method, headers: {}, credentials: "same-origin" };
  if (TOKEN) options.headers["X-Studio-Token"] = TOKEN;
  if (body !== undefined) {
    options.headers["Content-Type"] = "application/json";  // the server refuses other bodies
    options.body = JSON.stringify(body);
  }
  const response = await fetch(url, options);
  let data;
  try { data = await response.json(); } catch (e) { data = { error: `${response.status} ${response.statusText}` }; }
  if (!response.ok) throw new ApiError(data.error || `${response.status} ${response.statusText}`, response.status);
  return data;
}

// ------------------------------------------------------------------ messages

function say(text, kind) {
  const box = $("message");
  box.textContent = text;
  box.className = kind || "";
}
const sayError = (text) => say(text, "error");

// ------------------------------------------------------------------ the model

const doc = () => S.docs[S.domain];
const pattern = () => doc().patterns[doc().current];
const fullName = (p, i) => p.subgoals[i].name || `sg${i + 1}`;
const isGrid = () => S.geometry && S.geometry.kind === "grid";
const isForm = () => S.geometry && S.geometry.kind === "form";     // boxes over named components
const isTable = () => S.geometry && S.geometry.kind === "table";
const canTry = () => Object.keys(S.domains[S.domain].limits).length > 0;

// a new pattern's name: the first free one the domain asks for (PointMaze: its routes), else pattern_N
function newPattern(d, domain) {
  const taken = new Set(d ? d.patterns.map((p) => p.name) : []);
  const named = ((S.domains[domain] || {}).pattern_names || []).find((n) => !taken.has(n));
  if (named) return { name: named, subgoals: [], partial: false, edges: [] };
  let i = 1;
  while (taken.has(`pattern_${i}`)) i += 1;
  return { name: `pattern_${i}`, subgoals: [], partial: false, edges: [] };
}

function newDoc(domain) {
  // saved: the file as last saved or opened (for the download link); recipe: the command that trains with it
  const d = { file: `${domain}_subgoals.yaml`, patterns: [], current: 0, saved: null, recipe: "" };
  d.patterns.push(newPattern(d, domain));
  return d;
}

// a pattern as the server's drawing format: names only where given, order as name pairs
function toRequest(p) {
  return {
    name: p.name,
    subgoals: p.subgoals.map((s) => {
      const out = Object.assign({}, s);
      if (!out.name) delete out.name;
      return out;
    }),
    order: p.partial ? p.edges.map(([a, b]) => [fullName(p, a), fullName(p, b)]) : null,
    description: p.description || null,  // not edited here; kept from the file
  };
}

function fromDocument(p) {
  const subgoals = p.subgoals.map((s) => Object.assign({}, s, { name: s.name || null }));
  const model = { name: p.name, subgoals, partial: p.order !== null, edges: [], description: p.description };
  if (p.order) {
    const names = subgoals.map((s, i) => fullName(model, i));
    model.edges = p.order.map(([a, b]) => [names.indexOf(a), names.indexOf(b)]);
  }
  return model;
}

function drawing(patterns) {
  return { domain: S.domain, map: S.map, file: doc().file, description: doc().description || null,
    patterns: patterns.map(toRequest) };
}

const signature = (p) => JSON.stringify(toRequest(p));

function changed() {
  render();
  scheduleValidate();
}

// ------------------------------------------------------------------ validation

function scheduleValidate() {
  clearTimeout(S.validateTimer);
  S.validateTimer = setTimeout(validate, 200);
}

async function validate() {
  const seq = ++S.validateSeq;
  const d = doc();
  const empty = d.patterns.find((p) => p.subgoals.length === 0);
  if (empty) {
    say(`Pattern '${empty.name}' has no subgoals yet: click on the map to place the first one.`, "");
    return;
  }
  try {
    await api("POST", "/api/validate", drawing(d.patterns));
    if (seq !== S.validateSeq) return;
    const n = d.patterns.length;
    say(`✓ ${n} pattern${n > 1 ? "s" : ""}, valid: ready to save and to try.`, "ok");
  } catch (e) {
    if (seq === S.validateSeq) sayError(e.message);
  }
}

// which subgoals a local look says are off the map (drawn red); the server's message says why
function looksInvalid(s) {
  const g = S.geometry;
  if (!g) return false;
  if (s.cell) {
    const [r, c] = s.cell;
    return r < 0 || c < 0 || r >= g.rows.length || c >= g.rows[0].length || g.rows[r][c] === g.wall;
  }
  if (s.circle) {
    const [x, y] = s.circle.centre;
    const { x0, y0, x1, y1 } = plane();
    if (x < x0 || y < y0 || x > x1 || y > y1 || !(s.circle.radius > 0)) return true;
    return g.polygons.some((poly) => insidePolygon(x, y, poly));
  }
  return false;
}

function insidePolygon(x, y, poly) {
  let inside = false;
  for (let i = 0, j = poly.length - 1; i < poly.length; j = i++) {
    const [xi, yi] = poly[i];
    const [xj, yj] = poly[j];
    if ((yi > y) !== (yj > y) && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) inside = !inside;
  }
  return inside;
}

// ------------------------------------------------------------------ drawing the map

function fill(node, attrs, parent, text) {
  for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
  if (text !== undefined) node.textContent = text;
  if (parent) parent.appendChild(node);
  return node;
}
// an SVG element; html() makes an HTML one
const el = (name, attrs, parent, text) => fill(document.createElementNS(SVG_NS, name), attrs, parent, text);
const html = (name, attrs, parent, text) => fill(document.createElement(name), attrs, parent, text);

// A table's plane: world coordinates within geometry.bounds [xmin, ymin, xmax, ymax] (PinBall's unit
// square by default), y down as drawn, or up with geometry.y_up (PointMaze). The one place that converts
// world <-> SVG units: toSvg and toWorld.
function plane() {
  const g = S.geometry;
  const [x0, y0, x1, y1] = g.bounds || [0, 0, 1, 1];
  return { x0, y0, x1, y1, scale: VIEW / Math.max(x1 - x0, y1 - y0), yUp: Boolean(g.y_up) };
}

function toSvg(x, y) {
  const { x0, y0, y1, scale, yUp } = plane();
  return [(x - x0) * scale, (yUp ? y1 - y : y - y0) * scale];
}

// SVG units -> world coordinates, clamped to the plane and rounded to 4 decimals
function toWorld(px, py) {
  const { x0, y0, x1, y1, scale, yUp } = plane();
  const round = (v, lo, hi) => Math.round(Math.min(hi, Math.max(lo, v)) * 10000) / 10000;
  return [round(x0 + px / scale, x0, x1), round(yUp ? y1 - py / scale : y0 + py / scale, y0, y1)];
}

function cellSize() {
  const g = S.geometry;
  return VIEW / Math.max(g.rows.length, g.rows[0].length);
}

// centre of a subgoal in SVG units, and its drawn radius
function place(s) {
  if (s.cell) {
    const k = cellSize();
    return { x: (s.cell[1] + 0.5) * k, y: (s.cell[0] + 0.5) * k, r: k * 0.42 };
  }
  const [x, y] = toSvg(...s.circle.centre);
  return { x, y, r: Math.max(3, s.circle.radius * plane().scale) };
}

function renderMap() {
  const svg = $("map-view");
  svg.replaceChildren();
  svg.setAttribute("viewBox", `0 0 ${VIEW} ${VIEW}`);
  const g = S.geometry;
  svg.toggleAttribute("hidden", Boolean(isForm()));
  $("box-form").hidden = !isForm();
  if (!g) return;
  if (isForm()) {
    renderForm();
    return;
  }
  const defs = el("defs", {}, svg);
  const marker = el("marker", { id: "head", viewBox: "0 0 10 10", refX: 9, refY: 5, markerWidth: 7, markerHeight: 7,
    orient: "auto-start-reverse" }, defs);
  el("path", { d: "M 0 0 L 10 5 L 0 10 z", fill: "#0a3069" }, marker);

  if (g.kind === "grid") {
    const k = cellSize();
    const halls = new Set(g.hallways.map(([r, c]) => `${r},${c}`));
    g.rows.forEach((row, r) => [...row].forEach((ch, c) => {
      const kind = ch === g.wall ? "wall" : halls.has(`${r},${c}`) ? "hallway" : "free";
      el("rect", { x: c * k, y: r * k, width: k, height: k, class: `cell ${kind}`, "data-row": r, "data-col": c }, svg);
    }));
    for (const [label, [r, c]] of [["S", g.start], ["G", g.goal]]) {
      el("text", { x: (c + 0.5) * k, y: (r + 0.5) * k + 6, "text-anchor": "middle", class: "landmark" }, svg, label);
    }
  } else {
    const { scale } = plane();
    el("rect", { x: 0, y: 0, width: VIEW, height: VIEW, fill: "#fff" }, svg);
    for (const poly of g.polygons) {
      el("polygon", { points: poly.map(([x, y]) => toSvg(x, y).join(",")).join(" "), class: "obstacle" }, svg);
    }
    // the start and target of the route the pattern is named after (PointMaze), else the map's
    const ends = (g.routes || {})[pattern().name] || g;
    const [tx, ty] = toSvg(ends.target[0], ends.target[1]);
    el("circle", { cx: tx, cy: ty, r: ends.target[2] * scale, class: "target" }, svg);
    const [sx, sy] = toSvg(ends.start[0], ends.start[1]);
    el("circle", { cx: sx, cy: sy, r: Math.max(4, g.ball_radius * scale), class: "start" }, svg);
  }

  // the file's other patterns, faintly
  doc().patterns.forEach((p, pi) => {
    if (pi === doc().current) return;
    for (const s of p.subgoals) {
      const { x, y, r } = place(s);
      if (s.cell) el("rect", { x: x - r, y: y - r, width: 2 * r, height: 2 * r, class: "ghost" }, svg);
      else el("circle", { cx: x, cy: y, r, class: "ghost" }, svg);
    }
  });

  const p = pattern();
  const edges = p.partial ? p.edges : p.subgoals.slice(1).map((_, i) => [i, i + 1]);
  for (const [a, b] of edges) {
    if (!p.subgoals[a] || !p.subgoals[b] || a === b) continue;
    const A = place(p.subgoals[a]);
    const B = place(p.subgoals[b]);
    const d = Math.hypot(B.x - A.x, B.y - A.y);
    if (d < A.r + B.r + 4) continue;
    const ux = (B.x - A.x) / d;
    const uy = (B.y - A.y) / d;
    el("line", { x1: A.x + ux * A.r, y1: A.y + uy * A.r, x2: B.x - ux * (B.r + 2), y2: B.y - uy * (B.r + 2),
      class: "arrow", "marker-end": "url(#head)" }, svg);
  }

  const values = currentValues();
  p.subgoals.forEach((s, i) => {
    const { x, y, r } = place(s);
    const classes = ["subgoal"];
    if (i === S.selected) classes.push("selected");
    if (looksInvalid(s)) classes.push("invalid");
    const group = el("g", { class: classes.join(" "), "data-index": i }, svg);
    if (s.cell) el("rect", { x: x - r, y: y - r, width: 2 * r, height: 2 * r, rx: 4 }, group);
    else el("circle", { cx: x, cy: y, r }, group);
    el("text", { x, y: y + 5, "text-anchor": "middle" }, group, String(i + 1));
    el("title", {}, group, `${fullName(p, i)}: ${where(s)}`);
    if (values) {
      el("text", { x, y: y + r + 12, "text-anchor": "middle", class: "value" }, group, `V=${fmt(values[i + 1])}`);
    }
  });
}

function where(s) {
  if (s.cell) return `(${s.cell[0]}, ${s.cell[1]})`;
  if (s.box) {
    const m = Array.isArray(s.box.margin) ? `[${s.box.margin.join(", ")}]` : s.box.margin;
    return `${s.box.components.join(" + ")} = [${s.box.centre.join(", ")}] ± ${m}`;
  }
  const [x, y] = s.circle.centre;
  return `(${x.toFixed(3)}, ${y.toFixed(3)}) r ${s.circle.radius}`;
}

function fmt(v) {
  if (v === undefined || v === null || Number.isNaN(v)) return "–";
  const a = Math.abs(v);
  return a >= 1000 ? v.toFixed(0) : a >= 10 ? v.toFixed(1) : v.toFixed(3);
}

// ------------------------------------------------------------------ map editing

function toModel(event) {
  const svg = $("map-view");
  const point = svg.createSVGPoint();
  point.x = event.clientX;
  point.y = event.clientY;
  const p = point.matrixTransform(svg.getScreenCTM().inverse());
  if (isGrid()) {
    const k = cellSize();
    return { cell: [Math.floor(p.y / k), Math.floor(p.x / k)], px: p.x, py: p.y };
  }
  return { centre: toWorld(p.x, p.y), px: p.x, py: p.y };
}

function moveTo(s, at) {
  if (s.cell) s.cell = at.cell;
  else s.circle.centre = at.centre;
}

// ------------------------------------------------------------------ the box form (pick-and-place)

const componentSize = (name) => S.geometry.components.find((c) => c.name === name).size;

// "0.01" -> 0.01, "0.01, 0.02" -> [0.01, 0.02]; anything else is sent as typed (the server says what is wrong)
function parseMargin(text) {
  const parts = text.split(/[\s,]+/).filter((x) => x !== "");
  const numbers = parts.map(Number);
  if (parts.length === 0 || numbers.some(Number.isNaN)) return text;
  return numbers.length === 1 ? numbers[0] : numbers;
}

function newBox() {
  const components = S.newComponents.slice();
  if (components.length === 0) {
    sayError("Tick at least one observation component for the new subgoal.");
    return;
  }
  const size = components.reduce((n, c) => n + componentSize(c), 0);
  pattern().subgoals.push({ name: null, box: { components, centre: new Array(size).fill(0),
    margin: S.geometry.default_margin } });
  S.selected = pattern().subgoals.length - 1;
  changed();
}

// a field edit: the model changes, the form keeps its inputs (and the focus); the server checks it
function edited() {
  renderPanels();
  scheduleValidate();
}

function renderForm() {
  const form = $("box-form");
  form.replaceChildren();
  const g = S.geometry;
  if (S.newComponents === null) S.newComponents = (g.ticked || []).slice();
  const add = html("fieldset", { class: "new-box" }, form);
  html("legend", {}, add, "New subgoal: a box over these observation components");
  const boxes = document.createElement("div");
  boxes.className = "components";
  for (const c of g.components) {
    const label = document.createElement("label");
    const check = document.createElement("input");
    check.type = "checkbox";
    check.value = c.name;
    check.checked = S.newComponents.includes(c.name);
    check.addEventListener("change", () => {
      S.newComponents = g.components.map((x) => x.name).filter((n) =>
        n === c.name ? check.checked : S.newComponents.includes(n));
    });
    label.append(check, ` ${c.name} `);
    const dims = document.createElement("small");
    dims.textContent = (c.size > 1 ? `[${c.start}–${c.start + c.size - 1}]` : `[${c.start}]`) +
      (c.range ? ` in [${c.range.join(", ")}]` : "");
    label.append(dims);
    boxes.appendChild(label);
  }
  add.appendChild(boxes);
  const addButton = button("+ Subgoal", "add a box subgoal over the ticked components, at the end of the order", newBox);
  addButton.id = "add-box";
  add.appendChild(addButton);

  const p = pattern();
  p.subgoals.forEach((s, i) => {
    const card = html("fieldset", { class: i === S.selected ? "box-card selected" : "box-card", "data-index": i }, form);
    html("legend", {}, card, `${i + 1}. ${fullName(p, i)}`);
    const table = document.createElement("table");
    let k = 0;
    for (const name of s.box.components) {
      const tr = document.createElement("tr");
      const th = document.createElement("th");
      th.textContent = name;
      tr.appendChild(th);
      const size = g.components.some((c) => c.name === name) ? componentSize(name) : 0;
      for (let j = 0; j < size; j += 1) {
        const index = k + j;
        const td = document.createElement("td");
        const input = document.createElement("input");
        input.type = "number";
        input.step = "0.01";
        input.className = "box-value";
        input.value = s.box.centre[index] ?? "";
        input.setAttribute("aria-label", `${name}[${j}] of subgoal ${i + 1}`);
        input.addEventListener("change", () => {
          const v = parseFloat(input.value);
          s.box.centre[index] = Number.isNaN(v) ? null : v;
          S.selected = i;
          edited();
        });
        td.appendChild(input);
        tr.appendChild(td);
      }
      k += size;
      table.appendChild(tr);
    }
    card.appendChild(table);
    const row = document.createElement("div");
    row.className = "row";
    const label = document.createElement("label");
    const margin = document.createElement("input");
    margin.className = "box-margin";
    margin.value = Array.isArray(s.box.margin) ? s.box.margin.join(", ") : String(s.box.margin);
    margin.title = "one margin for every coordinate, or one per coordinate separated by commas";
    margin.setAttribute("aria-label", `margin of subgoal ${i + 1}`);
    margin.addEventListener("change", () => { s.box.margin = parseMargin(margin.value); S.selected = i; edited(); });
    label.append("margin ±", margin);
    row.appendChild(label);
    card.appendChild(row);
  });
  if (p.subgoals.length === 0) {
    html("p", { class: "hint" }, form, "No subgoals yet: tick components above and press “+ Subgoal”.");
  }
}

function newSubgoal(at) {
  if (at.cell) return { name: null, cell: at.cell };
  const radius = parseFloat($("radius").value) || S.geometry.default_radius;
  return { name: null, circle: { centre: at.centre, radius } };
}

function onPointerDown(event) {
  if (event.button !== 0) return;
  const hit = event.target.closest("[data-index]");
  S.drag = { index: hit ? Number(hit.dataset.index) : null, x: event.clientX, y: event.clientY, moved: false };
  $("map-view").setPointerCapture(event.pointerId);
  event.preventDefault();
}

function onPointerMove(event) {
  const drag = S.drag;
  if (!drag || drag.index === null) return;
  if (!drag.moved && Math.hypot(event.clientX - drag.x, event.clientY - drag.y) < DRAG_START) return;
  drag.moved = true;
  S.selected = drag.index;
  moveTo(pattern().subgoals[drag.index], toModel(event));
  renderMap();
}

function onPointerUp(event) {
  const drag = S.drag;
  S.drag = null;
  if (!drag) return;
  const p = pattern();
  if (drag.index === null) {
    p.subgoals.push(newSubgoal(toModel(event)));
    S.selected = p.subgoals.length - 1;
  } else if (!drag.moved) {
    S.selected = drag.index;
    render();
    return;
  }
  changed();
}

function onContextMenu(event) {
  const hit = event.target.closest("[data-index]");
  if (!hit) return;
  event.preventDefault();
  removeSubgoal(Number(hit.dataset.index));
}

function removeSubgoal(i) {
  const p = pattern();
  p.subgoals.splice(i, 1);
  p.edges = p.edges.filter(([a, b]) => a !== i && b !== i).map(([a, b]) => [a > i ? a - 1 : a, b > i ? b - 1 : b]);
  S.selected = null;
  changed();
}

function swapSubgoals(i, j) {
  const p = pattern();
  if (j < 0 || j >= p.subgoals.length) return;
  [p.subgoals[i], p.subgoals[j]] = [p.subgoals[j], p.subgoals[i]];
  const swap = (k) => (k === i ? j : k === j ? i : k);
  p.edges = p.edges.map(([a, b]) => [swap(a), swap(b)]);
  S.selected = j;
  changed();
}

// ------------------------------------------------------------------ the side panel

function button(text, title, onClick) {
  const b = document.createElement("button");
  b.textContent = text;
  b.title = title;
  b.addEventListener("click", onClick);
  return b;
}

function renderPanels() {
  const d = doc();
  const p = pattern();
  $("file-name").value = d.file;
  $("recipe").textContent = d.recipe ? `Train with it: ${d.recipe}` : "";
  $("download").hidden = !d.saved;
  if (d.saved) {
    const query = TOKEN ? `?${new URLSearchParams({ token: TOKEN })}` : "";
    $("download").href = `/files/${encodeURIComponent(d.saved)}${query}`;
  }

  const chips = $("patterns");
  chips.replaceChildren();
  d.patterns.forEach((q, i) => {
    const li = document.createElement("li");
    const b = button(`${q.name} (${q.subgoals.length})`, "edit this pattern", () => {
      d.current = i;
      S.selected = null;
      render();
    });
    if (i === d.current) b.classList.add("current");
    li.appendChild(b);
    chips.appendChild(li);
  });
  if (document.activeElement !== $("pattern-name")) $("pattern-name").value = p.name;
  $("delete-pattern").disabled = d.patterns.length < 2;

  const list = $("subgoals");
  list.replaceChildren();
  p.subgoals.forEach((s, i) => {
    const li = document.createElement("li");
    li.dataset.index = i;
    if (i === S.selected) li.classList.add("selected");
    if (looksInvalid(s)) li.classList.add("invalid");
    const name = document.createElement("input");
    name.className = "sg-name";
    name.placeholder = `sg${i + 1}`;
    name.value = s.name || "";
    name.setAttribute("aria-label", `name of subgoal ${i + 1}`);
    name.addEventListener("change", () => { s.name = name.value.trim() || null; changed(); });
    const at = document.createElement("span");
    at.className = "where";
    at.textContent = s.circle ? `(${s.circle.centre[0].toFixed(3)}, ${s.circle.centre[1].toFixed(3)})` : where(s);
    li.append(name, " ", at, " ");
    if (s.circle) {
      const radius = document.createElement("input");
      radius.type = "number";
      radius.step = "0.01";
      radius.className = "sg-radius";
      radius.value = s.circle.radius;
      radius.title = "radius";
      radius.setAttribute("aria-label", `radius of subgoal ${i + 1}`);
      radius.addEventListener("change", () => { s.circle.radius = parseFloat(radius.value); changed(); });
      li.append("r ", radius, " ");
    }
    li.append(
      button("↑", "earlier in the order", () => swapSubgoals(i, i - 1)),
      button("↓", "later in the order", () => swapSubgoals(i, i + 1)),
      button("✕", "remove (or right-click it on the map)", () => removeSubgoal(i)),
    );
    list.appendChild(li);
  });

  $("radius-row").hidden = !isTable();
  $("partial").checked = p.partial;
  $("order-panel").hidden = !p.partial;
  const edges = $("edges");
  edges.replaceChildren();
  p.edges.forEach(([a, b], k) => {
    const li = document.createElement("li");
    li.append(`${a + 1}. ${fullName(p, a)} → ${b + 1}. ${fullName(p, b)} `,
      button("✕", "remove this arrow", () => { p.edges.splice(k, 1); changed(); }));
    edges.appendChild(li);
  });
  for (const id of ["edge-from", "edge-to"]) {
    const select = $(id);
    const keep = select.value;
    select.replaceChildren(...p.subgoals.map((s, i) => new Option(`${i + 1}. ${fullName(p, i)}`, String(i))));
    if (keep && Number(keep) < p.subgoals.length) select.value = keep;
  }

  const running = S.job !== null;
  $("try").disabled = running || !canTry();
  $("cancel").hidden = !running;
  $("hint").textContent = isGrid()
    ? "Click a cell to add the next subgoal · drag to move · right-click to remove. S: start, G: goal; shaded: hallways."
    : isForm()
      ? `A subgoal is reached where each ticked component's coordinates lie within target ± margin (the ${S.geometry.observation_size}-d observation's entries in brackets). Reorder or remove on the right.`
      : "Click to add the next subgoal circle · drag to move · right-click to remove. Blue: start, red: target.";
}

function render() {
  if (!S.job) setStatus("", "");
  renderMap();
  renderPanels();
  renderResult();
}

// ------------------------------------------------------------------ files

async function refreshFiles(selected) {
  try {
    const data = await api("GET", "/api/files");
    const list = $("file-list");
    list.replaceChildren(...data.files.map((f) => new Option(f.name, f.name)));
    if (data.files.length === 0) list.appendChild(new Option("no saved files yet", ""));
    if (selected) list.value = selected;
    $("open").disabled = data.files.length === 0;
  } catch (e) {
    sayError(e.message);
  }
}

async function save() {
  clearTimeout(S.validateTimer);
  S.validateSeq += 1; // a validation still in flight must not overwrite "Saved" (the server validates the save)
  const d = doc();
  d.file = $("file-name").value.trim();
  const url = `/api/files/${encodeURIComponent(d.file)}`;
  // the file this page opened or saved is saved over without asking; any other existing file is
  // a conflict (409) that the user confirms
  const own = Boolean(d.saved) && (d.file === d.saved || `${d.file}.yaml` === d.saved);
  try {
    let data;
    try {
      data = await api("PUT", own ? `${url}?overwrite=1` : url, drawing(d.patterns));
    } catch (e) {
      if (!(e instanceof ApiError) || e.status !== 409 || own) throw e;
      if (!window.confirm(`${e.message.split(";")[0]}. Replace it?`)) {
        say(`Not saved: ${e.message}`, "error");
        return;
      }
      data = await api("PUT", `${url}?overwrite=1`, drawing(d.patterns));
    }
    Object.assign(d, { file: data.file, saved: data.file, recipe: data.recipe });
    history.replaceState(null, "", pageUrl(data.file));
    say(`Saved ${data.path} (${data.patterns.length} pattern${data.patterns.length > 1 ? "s" : ""}).`, "ok");
    await refreshFiles(data.file);
    renderPanels();
  } catch (e) {
    sayError(e.message);
  }
}

async function openFile(name) {
  try {
    const data = await api("GET", `/api/files/${encodeURIComponent(name)}`);
    if (data.domain !== S.domain) await setDomain(data.domain);
    S.docs[data.domain] = { file: data.file, patterns: data.patterns.map(fromDocument), current: 0,
      saved: data.file, recipe: data.recipe, description: data.description };
    S.selected = null;
    history.replaceState(null, "", pageUrl(data.file));
    render();
    await validate();
    if ($("message").className === "ok") say(`Opened ${data.file}: ${data.patterns.length} pattern(s).`, "ok");
  } catch (e) {
    sayError(e.message);
  }
}

// ------------------------------------------------------------------ domains and maps

async function loadGeometry() {
  const query = new URLSearchParams({ domain: S.domain, map: S.map });
  S.geometry = await api("GET", `/api/geometry?${query}`);
  if (isTable()) {
    const { x0, y0, x1, y1 } = plane();
    $("radius").max = Math.max(x1 - x0, y1 - y0) / 2;  // PinBall: 0.5
    $("radius").value = S.geometry.default_radius;
  }
}

async function setDomain(name) {
  S.domain = name;
  const info = S.domains[name];
  $("domain").value = name;
  $("map").replaceChildren(...info.maps.map((m) => new Option(m, m)));
  $("map-label").hidden = info.maps.length === 0;
  S.map = info.maps.length ? info.maps[0] : "";
  if (!S.docs[name]) S.docs[name] = newDoc(name);
  S.newComponents = null;  // the form's ticks are the new domain's
  for (const key of ["episodes", "learners"]) {
    const input = $(key);
    const limit = info.limits[key];
    input.disabled = !limit;
    if (!limit) continue;
    input.min = limit.min;
    input.max = limit.max;
    input.value = limit.default;
  }
  $("episodes").closest(".row").hidden = Object.keys(info.limits).length === 0;
  $("try").closest(".row").hidden = Object.keys(info.limits).length === 0;
  $("try-note").textContent = info.try_note ||
    "A short learning with this pattern against the same learner without shaping (same seeds).";
  S.selected = null;
  await loadGeometry();
}

// ------------------------------------------------------------------ Try it

function resultKey(p) { return `${S.domain}/${p.name}`; }

function currentValues() {
  const entry = S.results[resultKey(pattern())];
  return entry ? entry.result.potential : null;
}

async function tryIt() {
  clearTimeout(S.validateTimer);
  S.validateSeq += 1; // a validation still in flight must not overwrite the answer to this try (the server validates it)
  const p = pattern();
  const body = Object.assign(drawing([p]), {
    pattern: p.name, method: $("method").value, episodes: Number($("episodes").value),
    learners: Number($("learners").value),
  });
  try {
    const job = await api("POST", "/api/try", body);
    S.job = { id: job.id, domain: S.domain, pattern: p.name, signature: signature(p) };
    $("try-progress").hidden = false;
    $("try-progress").value = 0;
    setStatus("running", "starting…");
    renderPanels();
    poll();
  } catch (e) {
    sayError(e.message);
  }
}

function setStatus(state, text) {
  const status = $("try-status");
  status.dataset.state = state;
  status.textContent = text;
}

async function poll() {
  const job = S.job;
  if (!job) return;
  let status;
  try {
    status = await api("GET", `/api/try/${job.id}`);
  } catch (e) {
    S.job = null;
    setStatus("failed", "");
    sayError(e.message);
    renderPanels();
    return;
  }
  $("try-progress").value = status.progress;
  if (status.state === "running") {
    setStatus("running", `${Math.round(100 * status.progress)}% · ${status.seconds.toFixed(1)} s`);
    setTimeout(poll, 300);
    return;
  }
  S.job = null;
  $("try-progress").hidden = true;
  if (status.state === "done") {
    S.results[`${job.domain}/${job.pattern}`] = { result: status.result, signature: job.signature };
  }
  render();
  if (status.state === "done") {
    setStatus("done", `done in ${status.seconds.toFixed(1)} s`);
  } else if (status.state === "cancelled") {
    setStatus("cancelled", "cancelled");
  } else {
    setStatus("failed", "failed");
    sayError(status.error);
  }
}

async function cancel() {
  if (!S.job) return;
  try { await api("DELETE", `/api/try/${S.job.id}`); } catch (e) { sayError(e.message); }
}

// ------------------------------------------------------------------ results

function smooth(values, window) {
  const out = [];
  let sum = 0;
  for (let i = 0; i < values.length; i++) {
    sum += values[i];
    if (i >= window) sum -= values[i - window];
    out.push(sum / Math.min(i + 1, window));
  }
  return out;
}

function niceTicks(lo, hi, count) {
  const step0 = (hi - lo) / count;
  const mag = 10 ** Math.floor(Math.log10(step0));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= step0);
  const ticks = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9; v += step) ticks.push(v);
  return ticks;
}

function renderCurves(result) {
  const svg = $("curves");
  svg.replaceChildren();
  const W = 520, H = 250, L = 50, R = 10, T = 26, B = 36;
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const n = result.shaped.mean.length;
  const window = Math.max(1, Math.round(n / 40));
  const series = ["baseline", "shaped"].map((key) => {
    const mean = smooth(result[key].mean, window);
    const sem = smooth(result[key].sem, window);
    return { key, mean, lo: mean.map((m, i) => Math.max(1, m - sem[i])), hi: mean.map((m, i) => m + sem[i]) };
  });
  const all = series.flatMap((s) => [...s.lo, ...s.hi]);
  const ymin = Math.max(1, Math.min(...all) / 1.2);
  const ymax = Math.max(ymin * 2, ...all) * 1.1;
  const X = (i) => L + ((W - L - R) * i) / Math.max(1, n - 1);
  const Y = (v) => T + ((H - T - B) * (Math.log10(ymax) - Math.log10(Math.max(v, ymin)))) / (Math.log10(ymax) - Math.log10(ymin));
  const grid = el("g", { class: "grid" }, svg);
  const axis = el("g", { class: "axis" }, svg);
  const yticks = [];
  for (let e = Math.floor(Math.log10(ymin)); e <= Math.ceil(Math.log10(ymax)); e++) {
    for (const m of [1, 2, 5]) {
      const v = m * 10 ** e;
      if (v >= ymin && v <= ymax) yticks.push(v);
    }
  }
  for (const v of yticks) {
    el("line", { x1: L, x2: W - R, y1: Y(v), y2: Y(v) }, grid);
    el("text", { x: L - 5, y: Y(v) + 4, "text-anchor": "end" }, axis, String(v));
  }
  for (const t of niceTicks(1, n, 5)) {
    el("line", { x1: X(t - 1), x2: X(t - 1), y1: H - B, y2: H - B + 4 }, axis);
    el("text", { x: X(t - 1), y: H - B + 16, "text-anchor": "middle" }, axis, String(t));
  }
  el("line", { x1: L, x2: W - R, y1: H - B, y2: H - B }, axis);
  el("line", { x1: L, x2: L, y1: T, y2: H - B }, axis);
  el("text", { x: (L + W - R) / 2, y: H - 4, "text-anchor": "middle", class: "chart-label" }, svg, "episode");
  el("text", { x: 12, y: (T + H - B) / 2, "text-anchor": "middle", class: "chart-label",
    transform: `rotate(-90 12 ${(T + H - B) / 2})` }, svg, "steps per episode (log)");
  const labels = { shaped: `with the subgoals (${result.method || "HRS-D"})`, baseline: "no shaping" };
  series.forEach((s, k) => {
    const band = s.hi.map((v, i) => `${X(i)},${Y(v)}`).concat(s.lo.map((v, i) => `${X(i)},${Y(v)}`).reverse());
    el("polygon", { points: band.join(" "), class: `band ${s.key}` }, svg);
    el("polyline", { points: s.mean.map((v, i) => `${X(i)},${Y(v)}`).join(" "), class: `curve ${s.key}`,
      "data-series": s.key }, svg);
    const lx = L + 10 + 150 * k;
    el("line", { x1: lx, x2: lx + 20, y1: 10, y2: 10, class: `curve ${s.key}` }, svg);
    el("text", { x: lx + 24, y: 14, class: "chart-label" }, svg, labels[s.key]);
  });
  if (window > 1) {
    // under the axis, right-aligned: the legend takes the top row
    el("text", { x: W - R, y: H - 4, "text-anchor": "end", class: "chart-label" }, svg, `moving mean of ${window} episodes`);
  }
}

const average = (values) => values.reduce((a, b) => a + b, 0) / Math.max(1, values.length);

function renderResult() {
  const box = $("try-result");
  const p = pattern();
  const entry = S.results[resultKey(p)];
  box.hidden = !entry;
  if (!entry) return;
  const r = entry.result;
  const s = r.settings;
  $("result-title").textContent =
    `Try it: '${r.pattern}' (${r.method || "HRS-D"}) · ${s.learners} learner${s.learners > 1 ? "s" : ""} × ${s.episodes} episodes · ${r.seconds.toFixed(1)} s`;
  $("result-stale").hidden = entry.signature === signature(p);
  renderCurves(r);
  const n = r.shaped.mean.length;
  const head = Math.max(1, Math.round(n / 10));
  const part = (curve, from, to) => average(curve.mean.slice(from, to)).toFixed(1);
  $("result-summary").textContent =
    `Mean steps, first ${head} episodes: ${part(r.shaped, 0, head)} with the subgoals, ${part(r.baseline, 0, head)} without; ` +
    `last ${head}: ${part(r.shaped, n - head, n)} and ${part(r.baseline, n - head, n)}. ` +
    `Episodes reaching the goal: ${(100 * r.shaped.success).toFixed(0)}% and ${(100 * r.baseline.success).toFixed(0)}%.`;
  const body = $("values").querySelector("tbody");
  body.replaceChildren();
  $("values").hidden = r.potential.length === 0;  // NRS: no table
  $("values-caption").textContent = r.method === "SRS"
    ? "Fixed potential V(z) (the progress prior): the value of having reached each subgoal"
    : "Learned potential V(z): the value of having reached each subgoal (mean ± s.e. over learners)";
  const scale = Math.max(1e-12, ...r.potential.map(Math.abs));
  r.potential.forEach((v, z) => {
    const tr = document.createElement("tr");
    const reached = z === 0 ? "start (no subgoal yet)"
      : p.subgoals[z - 1] ? `${z}. ${fullName(p, z - 1)} ${where(p.subgoals[z - 1])}` : `subgoal ${z}`;
    const bar = document.createElement("span");
    bar.className = v < 0 ? "bar neg" : "bar";
    bar.style.width = `${(80 * Math.abs(v)) / scale}px`;
    const cells = [String(z), reached, `${fmt(v)} ± ${fmt(r.potential_sem[z])}`];
    cells.forEach((text, k) => {
      const td = document.createElement("td");
      td.textContent = text;
      if (k === 2) td.className = "num";
      tr.appendChild(td);
    });
    const td = document.createElement("td");
    td.appendChild(bar);
    tr.appendChild(td);
    body.appendChild(tr);
  });
}

// ------------------------------------------------------------------ start

function wire() {
  const svg = $("map-view");
  svg.addEventListener("pointerdown", onPointerDown);
  svg.addEventListener("pointermove", onPointerMove);
  svg.addEventListener("pointerup", onPointerUp);
  svg.addEventListener("contextmenu", onContextMenu);
  $("domain").addEventListener("change", async () => {
    await setDomain($("domain").value);
    history.replaceState(null, "", pageUrl(null));
    changed();
  });
  $("map").addEventListener("change", async () => {
    S.map = $("map").value;
    await loadGeometry();
    changed();
  });
  $("file-name").addEventListener("change", () => { doc().file = $("file-name").value.trim(); });
  $("save").addEventListener("click", save);
  $("open").addEventListener("click", () => { if ($("file-list").value) openFile($("file-list").value); });
  $("new").addEventListener("click", () => {
    S.docs[S.domain] = newDoc(S.domain);
    S.selected = null;
    history.replaceState(null, "", pageUrl(null));
    changed();
  });
  $("add-pattern").addEventListener("click", () => {
    const d = doc();
    d.patterns.push(newPattern(d, S.domain));
    d.current = d.patterns.length - 1;
    S.selected = null;
    changed();
  });
  $("delete-pattern").addEventListener("click", () => {
    const d = doc();
    if (d.patterns.length < 2) return;
    d.patterns.splice(d.current, 1);
    d.current = Math.max(0, d.current - 1);
    S.selected = null;
    changed();
  });
  $("pattern-name").addEventListener("change", () => { pattern().name = $("pattern-name").value.trim(); changed(); });
  $("partial").addEventListener("change", () => {
    const p = pattern();
    p.partial = $("partial").checked;
    p.edges = p.partial ? p.subgoals.slice(1).map((_, i) => [i, i + 1]) : [];
    changed();
  });
  $("add-edge").addEventListener("click", () => {
    const p = pattern();
    const a = Number($("edge-from").value);
    const b = Number($("edge-to").value);
    if (Number.isNaN(a) || Number.isNaN(b)) return;
    if (!p.edges.some(([x, y]) => x === a && y === b)) p.edges.push([a, b]);
    changed();
  });
  $("try").addEventListener("click", tryIt);
  $("cancel").addEventListener("click", cancel);
  document.addEventListener("keydown", (event) => {
    const typing = ["INPUT", "SELECT", "TEXTAREA"].includes(document.activeElement.tagName);
    if (!typing && S.selected !== null && (event.key === "Delete" || event.key === "Backspace")) {
      removeSubgoal(S.selected);
    }
  });
}

async function start() {
  wire();
  try {
    const domains = await api("GET", "/api/domains");
    for (const d of domains) S.domains[d.name] = d;
    $("domain").replaceChildren(...domains.map((d) => new Option(d.title, d.name)));
    await setDomain(domains[0].name);
    await refreshFiles();
    const file = new URLSearchParams(location.search).get("file");
    if (file) {
      await openFile(file);
    } else {
      render();
      validate();
    }
  } catch (e) {
    sayError(e.message);
  }
  document.body.dataset.ready = "true";
}

start();
