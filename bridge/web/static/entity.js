// "Add as entity": after a raw read of a configured device, a form that turns the register
// read into an entity of the device's mapping (api/entity/preview, api/entity/add). The
// preview follows every change of a field; the bridge checks the entity with its mapping
// loader and writes the device's override file (a shipped mapping is never edited).
// Uses app.js's helpers ($, el, api). Data only ever goes into textContent.
"use strict";

const entityForm = { read: null, timer: null, asked: 0, keyEdited: false };
const ENTITY_TYPES = ["u16", "s16", "u32", "s32", "f32", "f16", "u64", "s64", "f64", "ascii", "bool"];
const STATE_CLASSES = ["", "measurement", "total", "total_increasing"];

function entityField(label, control) {
  const span = el("span", null, "field");
  const name = el("label", label);
  name.htmlFor = control.id;
  span.append(name, control);
  return span;
}

function entityInput(name, value, size) {
  const input = el("input");
  Object.assign(input, { id: `entity-${name}`, name, value: value ?? "", size: size || 8 });
  return input;
}

function entitySelect(name, options) {
  const select = el("select");
  Object.assign(select, { id: `entity-${name}`, name });
  for (const option of options) select.append(el("option", option));
  return select;
}

function buildEntityForm() {
  const form = el("form", null, "panel");
  form.id = "entity-form";
  const set = el("fieldset");
  set.append(el("legend", "Add as entity"),
    el("p", "A read-only entity of the device's mapping, from the registers read above.", "note"));
  const controls = [
    ["Name", entityInput("name", "", 20)], ["Key", entityInput("key", "", 16)],
    ["Address", entityInput("address", "", 7)], ["Type", entitySelect("type", ENTITY_TYPES)],
    ["Word order", entitySelect("word_order", ["big", "little"])],
    ["Byte order", entitySelect("byte_order", ["big", "little"])],
    ["Scale", entityInput("scale", "1", 6)], ["Offset", entityInput("offset", "0", 6)],
    ["Decimals", entityInput("precision", "", 3)], ["Count", entityInput("count", "", 3)],
    ["Unit", entityInput("unit", "", 6)], ["Device class", entityInput("device_class", "", 12)],
    ["State class", entitySelect("state_class", STATE_CLASSES)],
  ];
  for (const [label, control] of controls) set.append(entityField(label, control));
  const preview = el("p", "", "result");
  Object.assign(preview, { id: "entity-preview" });
  preview.setAttribute("aria-live", "polite");
  const button = el("button", "Add");
  button.type = "submit";
  const status = el("p", "", "result");
  status.id = "entity-status";
  status.setAttribute("role", "status");
  set.append(el("span", "Home Assistant shows: ", "note"), preview, button, status);
  form.append(set);
  form.addEventListener("input", (e) => {
    if (e.target.name === "key") entityForm.keyEdited = true;
    if (e.target.name === "name" && !entityForm.keyEdited) form.elements.key.value = keyOf(e.target.value);
    schedulePreview(form);
  });
  form.addEventListener("change", () => schedulePreview(form));
  form.addEventListener("submit", (e) => {
    e.preventDefault();
    addEntity(form);
  });
  return form;
}

function keyOf(name) {
  return name.toLowerCase().normalize("NFKD").replace(/[^a-z0-9]+/g, "_").replace(/^[^a-z]+|_+$/g, "").slice(0, 64);
}

function entityProposal(form) {
  const f = form.elements;
  const read = entityForm.read;
  const proposal = { device: read.device, table: read.table, name: f.name.value.trim(), key: f.key.value.trim(),
    address: number(f.address.value), type: f.type.value, word_order: f.word_order.value,
    byte_order: f.byte_order.value };
  const numeric = { scale: f.scale.value, offset: f.offset.value };
  for (const [name, text] of Object.entries(numeric)) if (text.trim() !== "") proposal[name] = Number(text);
  for (const name of ["precision", "count"]) if (f[name].value.trim() !== "") proposal[name] = number(f[name].value);
  for (const name of ["unit", "device_class", "state_class"]) if (f[name].value.trim() !== "") proposal[name] = f[name].value.trim();
  if (read.table === "coil" || read.table === "discrete") proposal.type = "bool";
  const start = proposal.address - read.address;
  const words = read.values.slice(Math.max(start, 0));
  if (start >= 0 && words.length) proposal.words = words;
  return proposal;
}

function schedulePreview(form) {
  clearTimeout(entityForm.timer);
  entityForm.timer = setTimeout(() => previewEntity(form), 250);
}

async function entityCall(path, proposal) {
  const options = { method: "POST", credentials: "same-origin", headers: { "Content-Type": "application/json" },
    body: JSON.stringify(proposal) };
  const answer = await fetch(path, options);
  const data = await answer.json();
  if (data.status !== "ok") throw new Error((data.errors || [data.error]).join("; "));
  return data.data;
}

async function previewEntity(form) {
  const shown = $("#entity-preview");
  const asked = ++entityForm.asked;
  try {
    const proposal = entityProposal(form);
    if (!proposal.name || !proposal.key) throw new Error("give the entity a name");
    const data = await entityCall("api/entity/preview", proposal);
    if (asked !== entityForm.asked) return;  // a newer preview is on its way
    shown.className = "result";
    shown.textContent = data.unit ? `${data.text} ${data.unit}` : data.text;
  } catch (error) {
    if (asked !== entityForm.asked) return;
    shown.className = "result error";
    shown.textContent = error.message;
  }
}

async function addEntity(form) {
  const status = $("#entity-status");
  const button = $("button", form);
  button.disabled = true;
  status.className = "result";
  status.textContent = "adding…";
  try {
    const data = await entityCall("api/entity/add", entityProposal(form));
    status.textContent = `added ${data.key} to ${entityForm.read.device} (${data.mapping}); the device polls it now`;
  } catch (error) {
    status.className = "result error";
    status.textContent = error.message;
  } finally {
    button.disabled = false;
  }
}

// app.js tells of each raw read (the "raw-read" event): a read of a configured device
// gets the form, prefilled with the read's first address.
document.addEventListener("raw-read", (event) => {
  const { device, data } = event.detail;
  let form = $("#entity-form");
  if (!device) {
    if (form) form.hidden = true;
    return;
  }
  entityForm.read = { device, table: data.table, address: data.address, values: data.registers || data.bits };
  if (!form) {
    form = buildEntityForm();
    $("#read-form").after(form);
  }
  form.hidden = false;
  form.elements.address.value = data.address;
  $("#entity-preview").textContent = "";
  $("#entity-status").textContent = "";
});
