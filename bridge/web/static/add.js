// "Add a device" (#/add): pick a bus (or a new one), scan, see what each unit is, pick a
// mapping from the library, try it, save. Uses app.js's helpers ($, el, row, api, run,
// number, valueRow). Every request before Save only reads.
"use strict";

const adding = { ports: null, found: new Map(), searched: "", timer: 0, buses: "", mappings: new Map() };
const NEW_SERIAL = "\u0000serial";
const NEW_TCP = "\u0000tcp";

async function addStep(path, body) {
  const answer = await api(path, body);
  if (answer.status !== "ok") throw new Error(answer.error);
  return answer.data;
}

// --- the bus ---------------------------------------------------------------------------

function fillAddBuses() {
  const buses = page.overview ? page.overview.buses.map((b) => b.id) : [];
  const select = $("#add-bus");
  if (adding.buses === buses.join(",") && select.options.length) return;
  adding.buses = buses.join(",");
  const chosen = select.value;
  select.replaceChildren(...buses.map((id) => new Option(`${id} (configured)`, id)),
    new Option("a new serial bus…", NEW_SERIAL), new Option("a new TCP gateway…", NEW_TCP));
  if (chosen) select.value = chosen;
  showNewBus();
}

function showNewBus() {
  const kind = { [NEW_SERIAL]: "serial", [NEW_TCP]: "tcp" }[$("#add-bus").value] || "";
  for (const field of document.querySelectorAll("[data-new]")) field.hidden = field.dataset.new !== kind;
  $("#add-bus-id-field").hidden = !kind;
  $("#add-bus-id").value = kind === "tcp" ? "gateway" : "rs485";
  $("#add-save").disabled = true;
  if (kind === "serial") loadPorts();
}

async function loadPorts() {
  if (adding.ports) return;
  adding.ports = (await api("api/ports")).ports;
  const select = $("#add-port");
  select.replaceChildren(...adding.ports.map((p) =>
    new Option(p.description ? `${p.path} (${p.description})` : p.path, p.path)));
  if (!adding.ports.length) select.append(new Option("no serial port found", ""));
}

// The bus as the API takes it: a configured bus's id, or a new bus's settings.
function chosenBus() {
  const form = $("#add-scan-form").elements;
  const choice = form.bus.value;
  if (choice === NEW_SERIAL) {
    return { transport: "rtu", port: form.port.value, baudrate: number(form.baudrate.value),
      parity: form.parity.value, stopbits: number(form.stopbits.value) };
  }
  if (choice === NEW_TCP) {
    return { transport: "tcp", host: form.host.value.trim(), tcp_port: number(form.tcp_port.value) };
  }
  return choice;
}

// --- scan and identify -----------------------------------------------------------------

async function addScan() {
  const status = $("#add-scan-status");
  const bus = chosenBus();
  adding.bus = bus;
  status.textContent = "scanning…";
  const data = await addStep("api/add/scan", { bus, units: $("#add-units").value });
  const where = typeof bus === "string" ? `bus ${bus}` : "the new bus";
  status.textContent = `${data.found.length} of ${data.probed} units answered on ${where}`;
  adding.found = new Map();
  const table = $("#add-found");
  table.hidden = !data.found.length;
  $("tbody", table).replaceChildren(...data.found.map((f) => {
    const use = el("button", "Use");
    use.type = "button";
    use.addEventListener("click", () => useUnit(f.unit));
    use.setAttribute("aria-label", `Use unit ${f.unit}`);
    const cell = el("td");
    cell.append(use);
    return row([el("td", f.unit, "num"), f.answer, f.device || "–", el("td", "identifying…", "identity"), cell],
      { "data-unit": f.unit });
  }));
  if (!data.found.length) return;
  try {
    const identified = await addStep("api/add/identify", { bus, units: data.found.map((f) => f.unit) });
    for (const identity of identified.found) adding.found.set(identity.unit, identity);
  } catch (error) {
    status.textContent += ` (identify: ${error.message})`;
  }
  for (const cell of $("tbody", table).querySelectorAll("td.identity")) {
    const identity = adding.found.get(Number(cell.parentElement.dataset.unit));
    cell.textContent = identity ? identity.summary : "not identified";
  }
  const fresh = data.found.filter((f) => !f.device);
  if (fresh.length === 1) useUnit(fresh[0].unit);  // the one new unit: take it
}

// Fill the device form from a unit found: its unit, the mapping it was identified as.
function useUnit(unit) {
  $("#add-unit").value = unit;
  const identity = adding.found.get(unit);
  const best = identity && identity.matches.length ? identity.matches[0] : null;
  if (best) {
    $("#add-search").value = best.mapping;
    searchLibrary(best.mapping).then(() => {
      $("#add-mapping").value = best.mapping;
      suggestNames();
    }, () => {});
  }
  $("#add-unit").focus();
}

function suggestNames() {
  const option = $("#add-mapping").selectedOptions[0];
  showOptions();
  if (!option) return;
  const unit = $("#add-unit").value.trim();
  if (!$("#add-id").dataset.edited) $("#add-id").value = `${option.value}_${unit}`.slice(0, 64);
  if (!$("#add-name").dataset.edited) $("#add-name").value = option.dataset.model || "";
}

// The chosen mapping's model variants (its options), each a choice of its own.
function showOptions() {
  const mapping = adding.mappings.get($("#add-mapping").value);
  const box = $("#add-options");
  if (box.dataset.mapping === (mapping ? mapping.mapping : "")) return;
  box.dataset.mapping = mapping ? mapping.mapping : "";
  box.replaceChildren(...Object.entries(mapping ? mapping.options : {}).map(([name, option]) => {
    const field = el("span", null, "field");
    const label = el("label", name.replaceAll("_", " "));
    const select = el("select");
    select.id = `add-option-${name}`;
    select.dataset.option = name;
    label.htmlFor = select.id;
    label.title = option.description;
    select.append(...option.choices.map((choice) => new Option(choice, choice, false, choice === option.default)));
    field.append(label, select);
    return field;
  }));
}

function chosenOptions() {
  const options = {};
  for (const select of $("#add-options").querySelectorAll("select")) options[select.dataset.option] = select.value;
  return options;
}

// --- the library -----------------------------------------------------------------------

async function searchLibrary(query) {
  adding.searched = query;
  const data = await api(`api/library?q=${encodeURIComponent(query)}`);
  if (adding.searched !== query) return;  // a newer search is on its way
  const select = $("#add-mapping");
  const kept = select.value;
  for (const m of data.mappings) adding.mappings.set(m.mapping, m);
  select.replaceChildren(...data.mappings.map((m) => {
    const option = new Option(`${m.manufacturer} ${m.model} · ${m.category} (${m.mapping})`, m.mapping);
    option.dataset.model = `${m.manufacturer} ${m.model}`;
    return option;
  }));
  if (data.mappings.some((m) => m.mapping === kept)) select.value = kept;
  showOptions();
  if (data.total > data.mappings.length) {
    select.append(new Option(`… ${data.total - data.mappings.length} more: narrow the search`, ""));
  }
}

// --- try it ----------------------------------------------------------------------------

function proposed() {
  const form = $("#add-device-form").elements;
  const body = { bus: adding.bus ?? chosenBus(), unit: number(form.unit.value), mapping: form.mapping.value,
    options: chosenOptions() };
  if (form.name.value.trim()) body.name = form.name.value.trim();
  if (form.id.value.trim()) body.id = form.id.value.trim();
  return body;
}

async function tryIt() {
  const status = $("#add-trial-status");
  status.textContent = "reading once…";
  $("#add-refused").textContent = "";
  const data = await addStep("api/trial", proposed());
  const table = $("#add-values");
  table.hidden = false;
  $("tbody", table).replaceChildren(...data.values.map(valueRow));  // as the device page shows them
  status.textContent = data.note
    ? `${data.model}: ${data.note}`
    : `${data.model}: ${data.read} of ${data.values.length} values read in ${data.requests} requests`;
  $("#add-save").disabled = false;  // tried: it may be saved now
  if (data.refused.length) {
    $("#add-refused").textContent = "Refused by the device: " +
      data.refused.map((r) => `${r.table} ${r.address}`).join(", ");
  }
}

// --- save ------------------------------------------------------------------------------

// The device (and its new bus) written to the config file and applied by the bridge.
async function save() {
  const status = $("#add-save-status");
  const diff = $("#add-save-diff");
  const tried = proposed();
  const device = { id: tried.id, bus: tried.bus, unit: tried.unit, mapping: tried.mapping, options: tried.options };
  if (tried.name) device.name = tried.name;
  const body = { device };
  if (typeof tried.bus !== "string") {
    device.bus = $("#add-bus-id").value.trim();
    body.bus = { id: device.bus, ...tried.bus };
  }
  status.className = "result";
  status.textContent = "saving…";
  diff.hidden = true;
  const answer = await fetch("api/config/devices", { method: "POST", credentials: "same-origin",
    headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  const data = await answer.json();
  if (!answer.ok) {
    status.className = "result error";
    status.textContent = data.error;
    if (data.diff) {  // changed on disk: what changed there, nothing overwritten
      diff.textContent = data.diff;
      diff.hidden = false;
    }
    return;
  }
  const applied = data.data.applied;
  const link = el("a", `open ${device.id}`);
  link.href = `#/device/${encodeURIComponent(device.id)}`;
  status.replaceChildren(applied.status === "ok"
    ? `Saved and applied (${applied.description}): `
    : `Saved; the bridge applies it at its next start (${applied.error}): `, link);
  $("#add-save").disabled = true;
}

// --- wiring ----------------------------------------------------------------------------

function startAdding() {
  $("#add-bus").addEventListener("change", () => { adding.bus = undefined; showNewBus(); });
  $("#add-search").addEventListener("input", (e) => {
    clearTimeout(adding.timer);
    adding.timer = setTimeout(() => searchLibrary(e.target.value).catch(() => {}), 200);
  });
  $("#add-mapping").addEventListener("change", suggestNames);
  $("#add-save").addEventListener("click", () => {
    $("#add-save").disabled = true;
    save().catch((error) => {
      $("#add-save-status").className = "result error";
      $("#add-save-status").textContent = error.message;
      $("#add-save").disabled = false;
    });
  });
  for (const id of ["#add-id", "#add-name"]) {
    $(id).addEventListener("input", () => { $(id).dataset.edited = "yes"; });
  }
  for (const [id, work] of [["#add-scan-form", addScan], ["#add-device-form", tryIt]]) {
    const form = $(id);
    form.addEventListener("submit", (e) => {
      e.preventDefault();
      run(form, $(".result", form), work);
    });
  }
  const shown = () => {
    if (location.hash !== "#/add") return;
    fillAddBuses();
    if (!$("#add-mapping").options.length) searchLibrary("").catch(() => {});
  };
  window.addEventListener("hashchange", shown);
  // the configured buses come with the first overview: fill the list when they do
  const waiting = setInterval(() => { if (page.overview) { clearInterval(waiting); shown(); } }, 200);
  shown();
}

startAdding();
