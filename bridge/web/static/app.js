// The bridge's web page: plain DOM, no framework. Every URL is relative (Home Assistant
// ingress serves the page under a prefix). Data only ever goes into textContent.
"use strict";

const $ = (selector, root = document) => root.querySelector(selector);
const page = { overview: null, device: null, events: null, route: "", errors: [] };

// --- helpers ---------------------------------------------------------------------------

function el(tag, text, className) {
  const node = document.createElement(tag);
  if (text !== undefined && text !== null) node.textContent = String(text);
  if (className) node.className = className;
  return node;
}

function row(cells, attributes = {}) {
  const tr = document.createElement("tr");
  for (const [name, value] of Object.entries(attributes)) tr.setAttribute(name, value);
  for (const cell of cells) tr.append(cell instanceof Node ? cell : el("td", cell));
  return tr;
}

// Update a table body in place (a row whose cells did not change is left alone, so the
// keyboard focus on a link in it survives the once-a-second refresh).
function syncBody(body, rows, key) {
  const old = [...body.rows];
  const same = old.length === rows.length && old.every((r, i) => r.getAttribute(key) === rows[i].getAttribute(key));
  if (!same) {
    body.replaceChildren(...rows);
    return;
  }
  old.forEach((r, i) => patchRow(r, rows[i]));
}

function patchRow(old, fresh) {
  old.className = fresh.className;
  [...fresh.cells].forEach((cell, i) => {
    const target = old.cells[i];
    if (!target || target.textContent !== cell.textContent || target.className !== cell.className ||
        target.title !== cell.title) {
      if (target) target.replaceWith(cell); else old.append(cell);
    }
  });
}

function formatValue(value, decimals) {
  if (value === null || value === undefined) return "unknown";
  if (value === true) return "on";
  if (value === false) return "off";
  if (typeof value === "number" && Number.isFinite(value) && Number.isInteger(decimals)) {
    return value.toFixed(decimals);
  }
  return String(value);
}

// A value in Home Assistant's words (the JSON's text), the state document's own value
// (running_forward, true) kept as the cell's title and data-value.
function shown(tag, text, raw, className) {
  const node = el(tag, text ?? "–", className);
  const value = raw === null || raw === undefined ? "" : String(raw);
  node.dataset.value = value;
  if (value !== "" && value !== node.textContent) node.title = value;
  return node;
}

function time(iso) {
  return iso ? new Date(iso).toLocaleTimeString() : "never";
}

function ms(value) {
  return value === null || value === undefined ? "–" : `${value} ms`;
}

function number(text) {
  const trimmed = String(text).trim();
  if (trimmed === "") return undefined;
  const value = Number(trimmed);
  if (!Number.isInteger(value)) throw new Error(`${trimmed} is not a whole number`);
  return value;
}

// A GET, or a POST of JSON: its status and its answer whatever the status (a 409 carries
// what to confirm); the token asked for when the page has none.
async function apiAnswer(path, body) {
  const options = { credentials: "same-origin", headers: {} };
  if (body !== undefined) {
    options.method = "POST";
    options.headers["Content-Type"] = "application/json";
    options.body = JSON.stringify(body);
  }
  const answer = await fetch(path, options);
  if (answer.status === 401) {
    showLogin();
    throw new Error("this page needs its token");
  }
  let data = {};
  try { data = await answer.json(); } catch (error) { data = { error: `${answer.status}` }; }
  return { status: answer.status, data };
}

// The answer of a request that succeeded; its error said otherwise.
async function api(path, body) {
  const { status, data } = await apiAnswer(path, body);
  if ((status < 200 || status > 299) && data.error) throw new Error(data.error);
  return data;
}

// --- live data -------------------------------------------------------------------------

function connect(deviceId) {
  if (page.events) page.events.close();
  const url = "api/events" + (deviceId ? `?device=${encodeURIComponent(deviceId)}` : "");
  const events = new EventSource(url);
  page.events = events;
  events.addEventListener("open", () => setLink());
  events.addEventListener("overview", (e) => renderOverview(JSON.parse(e.data)));
  events.addEventListener("device", (e) => renderDevice(JSON.parse(e.data)));
  events.addEventListener("values", (e) => renderValues(JSON.parse(e.data)));
  events.addEventListener("errors", (e) => renderErrors(JSON.parse(e.data).reverse()));
  events.addEventListener("refused", (e) => renderErrors([JSON.parse(e.data), ...page.errors]));
  events.addEventListener("error", () => {
    setLink("reconnecting");
    if (events.readyState === EventSource.CLOSED) {
      // refused (token?) or the bridge restarted: find out, then try again
      api("api/overview").then(() => setTimeout(() => route(), 2000), () => {});
    }
  });
}

function setLink(trouble) {
  const mqtt = page.overview ? page.overview.mqtt : "…";
  const live = trouble || (page.events && page.events.readyState === EventSource.OPEN ? "live" : "connecting");
  // a subscription the broker does not hold (yet): commands cannot reach the bridge
  const held = (page.overview && page.overview.subscriptions) || {};
  const waiting = Object.keys(held).filter((name) => held[name] !== "live");
  const note = mqtt === "online" && waiting.length ? ` (not subscribed: ${waiting.join(", ")})` : "";
  $("#link").textContent = `MQTT ${mqtt}${note} · page ${live}`;
  $("#link").dataset.state = trouble ? "trouble" : note ? "trouble" : mqtt;
}

// --- pages -----------------------------------------------------------------------------

function renderOverview(overview) {
  page.overview = overview;
  setLink();
  $("#refused-count").textContent = overview.refused ? `(${overview.refused})` : "";
  syncBody($("#devices tbody"),
    overview.devices.map((d) => {
      const link = el("a", d.name);
      link.href = `#/device/${encodeURIComponent(d.id)}`;
      const name = el("th");
      name.scope = "row";
      name.append(link);
      const errors = `${d.errors} / ${d.requests}` + (d.alarms.length ? ` · alarms: ${d.alarm_names.join(", ")}` : "");
      return row(
        [name, d.model, `${d.bus} / ${d.unit}`, el("td", d.state, `state ${d.state}`),
         shown("td", d.status_text, d.status, "status"), el("td", time(d.last_success), "nowrap"),
         el("td", `${ms(d.latency_p50_ms)} / ${ms(d.latency_p95_ms)}`, "nowrap"), el("td", errors, d.alarms.length ? "alarm" : "")],
        { "data-device": d.id },
      );
    }), "data-device");
  syncBody($("#buses tbody"),
    overview.buses.map((b) => row(
      [el("th", b.id), b.transport, el("td", b.connected ? "connected" : "down", b.connected ? "state online" : "state offline"),
       el("td", `${(b.utilisation * 100).toFixed(1)} %`, "num"), el("td", b.requests_per_s.toFixed(1), "num"),
       el("td", b.requests, "num"), el("td", b.timeouts, "num"), el("td", b.frame_errors, "num"),
       el("td", b.exceptions, "num"), el("td", b.reopenings, "num")],
      { "data-bus": b.id },
    )), "data-bus");
  renderGateway(overview.gateway);
  fillSelects(overview);
  if (page.device) renderFacts(overview.devices.find((d) => d.id === page.device.id));
}

function renderGateway(gateway) {
  $("#gateway-state").textContent = gateway
    ? `Listening on port ${gateway.port}; bus transactions for other masters: ` +
      (Object.entries(gateway.bus_transactions).map(([bus, n]) => `${bus} ${n}`).join(", ") || "none")
    : "The Modbus TCP server is off (bridge.gateway).";
  const clients = gateway ? Object.entries(gateway.clients) : [];
  syncBody($("#gateway tbody"),
    clients.map(([peer, c]) => row(
      [el("th", peer), el("td", c.connections, "num"), el("td", c.requests, "num"),
       el("td", c.served, "num"), el("td", c.cached, "num"), el("td", c.queued, "num"),
       el("td", c.refused, "num"), el("td", c.failed, "num"), el("td", c.dropped, "num"),
       el("td", c.delayed, "num"), el("td", c.busy, "num")],
      { "data-client": peer },
    )), "data-client");
}

function fillSelects(overview) {
  for (const select of document.querySelectorAll(".bus-select")) {
    if (select.options.length === overview.buses.length) continue;
    select.replaceChildren(...overview.buses.map((b) => new Option(b.id, b.id)));
  }
  for (const select of document.querySelectorAll(".device-select")) {
    if (select.options.length === overview.devices.length + 1) continue;
    select.replaceChildren(new Option("(a unit on a bus)", ""),
      ...overview.devices.map((d) => new Option(`${d.name} (unit ${d.unit})`, d.id)));
  }
  const off = !overview.raw_writes;
  $("#write-off").hidden = !off;
  for (const field of $("#write-form").elements) if (field.tagName !== "FIELDSET") field.disabled = off;
}

function renderFacts(summary) {
  if (!summary) return;
  const facts = [["Model", summary.model], ["Bus / unit", `${summary.bus} / ${summary.unit}`],
    ["State", summary.state], ["Status", shown("dd", summary.status_text, summary.status, "status")],
    ["Last answer", time(summary.last_success)],
    ["Latency p50 / p95", `${ms(summary.latency_p50_ms)} / ${ms(summary.latency_p95_ms)}`],
    ["Errors", `${summary.errors} of ${summary.requests} requests (${summary.timeouts} timeouts)`]];
  if (summary.error) facts.push(["Why offline", summary.error]);
  if (page.device && page.device.topic) facts.push(["MQTT topic", page.device.topic]);
  $("#device-facts").replaceChildren(...facts.flatMap(([term, value]) => {
    const dd = value instanceof Node ? value : el("dd", value);
    if (term === "State") dd.className = `state ${summary.state}`;
    return [el("dt", term), dd];
  }));
  renderAlarms(summary);
}

// The active alarms by the names Home Assistant shows; their keys (what MQTT clients
// match) in the title.
function renderAlarms({ alarms, alarm_names: names }) {
  const box = $("#device-alarms");
  box.className = alarms.length ? "alarms" : "";
  box.textContent = alarms.length ? `Active alarms: ${names.join(", ")}` : "No active alarms";
  box.title = alarms.join(", ");
}

function renderDevice(device) {
  page.device = device;
  $("#device-title").textContent = device.name;
  renderFacts(device);
  $("#values tbody").replaceChildren(...device.values.map(valueRow));
}

function valueRow(v) {
  const name = el("th", v.name);
  name.scope = "row";
  if (v.alarm) name.append(" ", el("strong", "ALARM", "badge"));
  const reading = shown("td", v.text, v.value, "num value");
  return row([name, reading, v.unit || "", el("td", v.key, "key")],
    { "data-key": v.key, class: v.alarm ? "alarm" : "" });
}

function renderValues(change) {
  if (!page.device || change.device !== page.device.id) return;
  for (const [key, v] of Object.entries(change.values)) {
    const old = $(`#values tr[data-key="${CSS.escape(key)}"]`);
    if (!old) {
      api(`api/devices/${encodeURIComponent(page.device.id)}`).then(renderDevice, () => {});
      return;
    }
    patchRow(old, valueRow(v));
  }
  renderAlarms(change);
}

function renderErrors(errors) {
  page.errors = errors.slice(0, 50);
  $("#errors tbody").replaceChildren(...page.errors.map((e) => row(
    [time(e.time), e.device, e.key ?? "", e.value === undefined ? "" : JSON.stringify(e.value), e.error])));
}

async function showConfig() {
  const info = await api("api/config");
  $("#config-facts").replaceChildren(el("dt", "Version"), el("dd", info.version),
    el("dt", "Config file"), el("dd", info.config_file));
  $("#config").textContent = JSON.stringify(info.config, null, 2);
}

// --- commissioning ---------------------------------------------------------------------

function target(form) {
  const device = form.elements.device.value;
  if (device) return { device };
  return { bus: form.elements.bus.value, unit: number(form.elements.unit.value) };
}

async function run(form, status, work) {
  const button = $("button", form);
  button.disabled = true;
  status.className = "result";
  try {
    await work();
  } catch (error) {
    status.className = "result error";
    status.textContent = error.message;
  } finally {
    button.disabled = false;
  }
}

async function request(command, body) {
  const answer = await api(`api/request/${command}`, body);
  if (answer.status !== "ok") throw new Error(answer.error);
  return answer.data;
}

async function scan(form) {
  const status = $("#scan-status");
  status.textContent = "scanning…";
  const data = await request("device/scan", { bus: form.elements.bus.value, units: form.elements.units.value });
  status.textContent = `${data.found.length} of ${data.probed} units answered on ${data.bus}`;
  const table = $("#scan-result");
  table.hidden = false;
  $("tbody", table).replaceChildren(...data.found.map((f) => row(
    [el("td", f.unit, "num"), f.answer, f.detail, el("td", `${f.latency_ms} ms`, "num"), f.device || "–",
      el("td", "identifying…", "identity")],
    { "data-unit": f.unit })));
  if (data.found.length) await identify(data.bus, data.found.map((f) => f.unit), status);
}

// What each unit found is (device/identify, read-only), in the scan table's last column.
async function identify(bus, units, status) {
  const cells = () => $("#scan-result tbody").querySelectorAll("td.identity");
  try {
    const data = await request("device/identify", { bus, units });
    const found = new Map(data.found.map((f) => [f.unit, f]));
    for (const cell of cells()) {
      const identity = found.get(Number(cell.parentElement.dataset.unit));
      cell.textContent = identity ? identity.summary : "no answer";
      if (identity && identity.config) cell.title = `config:\n${identity.config}`;
    }
  } catch (error) {
    for (const cell of cells()) cell.textContent = "–";
    status.textContent += ` (identify: ${error.message})`;
  }
}

async function read(form) {
  const status = $("#read-status");
  status.textContent = "reading…";
  const data = await request("device/read", { ...target(form), table: form.elements.table.value,
    address: number(form.elements.address.value), count: number(form.elements.count.value) });
  status.textContent = `unit ${data.unit} on ${data.bus}, ${data.table} ${data.address}..${data.address + data.count - 1}`;
  $("#read-result").replaceChildren(...(data.words ? wordTables(data) : [bitTable(data)]));
  document.dispatchEvent(new CustomEvent("raw-read", { detail: { device: form.elements.device.value, data } }));
}

function table(headings, rows) {
  const t = el("table");
  const head = row(headings.map((h) => el("th", h)));
  t.append(el("thead"), el("tbody"));
  t.tHead.append(head);
  t.tBodies[0].append(...rows);
  const wrap = el("div", null, "scroll");
  wrap.append(t);
  return wrap;
}

function wordTables(data) {
  const words = table(["Address", "u16", "s16", "hex", "ASCII", "bits"],
    data.words.map((w) => row([el("td", w.address, "num"), el("td", w.u16, "num"), el("td", w.s16, "num"), w.hex, w.ascii, w.bits])));
  const orders = ["ABCD", "CDAB", "BADC", "DCBA"];
  const pairs = table(["Address", ...orders.flatMap((o) => [`${o} u32`, `${o} s32`, `${o} f32`])],
    data.pairs.map((p) => row([el("td", p.address, "num"), ...orders.flatMap((o) => [p[o].u32, p[o].s32, p[o].f32].map((x) => el("td", x, "num")))])));
  return data.pairs.length ? [words, el("h3", "Register pairs (32-bit, four byte orders)"), pairs] : [words];
}

function bitTable(data) {
  return table(["Address", "Bit"], data.bits.map((bit, i) => row([el("td", data.address + i, "num"), el("td", bit, "num")])));
}

async function write(form) {
  const status = $("#write-status");
  const values = form.elements.values.value.split(/[\s,]+/).filter(Boolean).map(number);
  const who = form.elements.device.value || `unit ${form.elements.unit.value} on ${form.elements.bus.value}`;
  const what = `${form.elements.table.value} ${form.elements.address.value}: ${values.join(", ")}`;
  if (!window.confirm(`Write ${what} to ${who}? This bypasses the mapping's checks.`)) return;
  status.textContent = "writing…";
  const data = await request("device/write", { ...target(form), table: form.elements.table.value,
    address: number(form.elements.address.value), values });
  status.textContent = `written with function ${data.function}: unit ${data.unit}, ${data.table} ${data.address} = ${data.values.join(", ")}`;
}

// --- routing ---------------------------------------------------------------------------

function showLogin() {
  if (page.events) page.events.close();
  page.events = null;
  for (const section of document.querySelectorAll("[data-page]")) section.hidden = true;
  $("#login").hidden = false;
  $("#token").focus();
}

function route() {
  const [, name = "devices", id] = (location.hash.match(/^#\/([a-z]+)(?:\/(.+))?/) || []);
  const section = $(`[data-page="${name}"]`) ? name : "devices";
  $("#login").hidden = true;
  for (const s of document.querySelectorAll("[data-page]")) s.hidden = s.dataset.page !== section;
  for (const a of document.querySelectorAll("nav a")) {
    a.toggleAttribute("aria-current", a.getAttribute("href") === `#/${section}`);
  }
  const deviceId = section === "device" && id ? decodeURIComponent(id) : null;
  if (!deviceId) page.device = null;
  const changed = page.route !== location.hash;
  page.route = location.hash;
  if (changed || !page.events) connect(deviceId);
  if (section === "config") showConfig().catch(() => {});
  if (changed) $(`[data-page="${section}"] h2`).focus();
}

function start() {
  $("#login-form").addEventListener("submit", async (e) => {
    e.preventDefault();
    try {
      await api("api/login", { token: $("#token").value });
      $("#token").value = "";
      $("#login-error").textContent = "";
      page.route = "";
      route();
    } catch (error) {
      $("#login-error").textContent = error.message;
    }
  });
  for (const [id, work] of [["#scan-form", scan], ["#read-form", read], ["#write-form", write]]) {
    const form = $(id);
    form.addEventListener("submit", (e) => {
      e.preventDefault();
      run(form, $(".result", form), () => work(form));
    });
  }
  window.addEventListener("hashchange", route);
  route();
}

start();
