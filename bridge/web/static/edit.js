// Edit and remove a configured device (api/config/devices/<id>): the Edit panel of a
// device's page, and the devices the bridge does not poll (disabled) on the Devices page.
// Uses app.js's helpers ($, el, page, route). Only the fields changed are sent; turning
// dangerous writes on shows what they permit and needs its own confirmation.
"use strict";

const editing = { device: null };

function devicePath(id, action) {
  return `api/config/devices/${encodeURIComponent(id)}` + (action ? `/${action}` : "");
}

// --- the panel -------------------------------------------------------------------------

async function showEdit(deviceId) {
  const panel = $("#edit");
  hideConfirm();
  $("#edit-diff").hidden = true;
  const { status, data } = await apiAnswer(devicePath(deviceId));
  if (status !== 200) {
    panel.hidden = true;
    editing.device = null;
    return;
  }
  editing.device = data;
  panel.hidden = false;
  const form = $("#edit-form").elements;
  form.name.value = data.name || "";
  form.name.placeholder = data.display_name;
  form.id.value = data.id;
  form.unit.value = data.unit;
  form.unit.max = data.max_unit;
  form.fast.value = data.poll.fast;
  form.slow.value = data.poll.slow;
  form.enabled.checked = data.enabled;
  form.dangerous.checked = data.allow_dangerous_writes;
  $("#edit-dangerous-note").textContent = data.dangerous.entities.length
    ? `${data.dangerous.entities.length} settings and commands are guarded`
    : "nothing of this mapping is guarded";
  for (const field of $("#edit-form").elements) if (field.tagName !== "FIELDSET") field.disabled = !data.writable;
  $("#edit-read-only").hidden = data.writable;
}

// A poll interval as the API takes it: seconds as a number, or a duration ("2min").
function interval(text) {
  const trimmed = String(text).trim();
  return /^\d+(\.\d+)?$/.test(trimmed) ? Number(trimmed) : trimmed;
}

function changedFields() {
  const was = editing.device;
  const form = $("#edit-form").elements;
  const fields = {};
  if (form.name.value.trim() !== (was.name || "")) fields.name = form.name.value.trim();
  if (form.id.value.trim() !== was.id) fields.id = form.id.value.trim();
  if (Number(form.unit.value) !== was.unit) fields.unit = number(form.unit.value);
  const poll = {};
  if (String(interval(form.fast.value)) !== String(was.poll.fast)) poll.fast = interval(form.fast.value);
  if (String(interval(form.slow.value)) !== String(was.poll.slow)) poll.slow = interval(form.slow.value);
  if (Object.keys(poll).length) fields.poll = poll;
  if (form.enabled.checked !== was.enabled) fields.enabled = form.enabled.checked;
  if (form.dangerous.checked !== was.allow_dangerous_writes) {
    fields.allow_dangerous_writes = form.dangerous.checked;
  }
  return fields;
}

async function saveEdit() {
  const status = $("#edit-status");
  const fields = changedFields();
  if (!Object.keys(fields).length) {
    status.textContent = "Nothing changed.";
    return;
  }
  status.textContent = "saving…";
  const path = devicePath(editing.device.id);
  let answer = await apiAnswer(path, fields);
  if (answer.status === 409 && answer.data.status === "confirm") {
    const asked = answer.data;
    status.textContent = "Waiting for your confirmation…";
    const yes = await confirmStep(
      `Allow dangerous writes on ${editing.device.display_name}? Home Assistant and MQTT ` +
        "could then write these settings and commands:",
      dangerousItems(asked), "Allow these writes");
    if (!yes) {
      status.textContent = "Nothing changed: dangerous writes stay off.";
      $("#edit-form").elements.dangerous.checked = false;
      return;
    }
    answer = await apiAnswer(path, { ...fields, confirmation: asked.token });
  }
  afterChange(answer, fields.id || editing.device.id);
}

function dangerousItems(asked) {
  const items = asked.entities.map((e) => {
    const what = e.permits === "any value" ? "" : ` (${e.permits})`;
    return e.name + what + (e.shown ? "" : " – not shown in Home Assistant");
  });
  if (asked.raw_writes) items.push("and raw writes (Commissioning) to its guarded registers");
  return items.length ? items : ["nothing: this mapping guards no entity"];
}

function afterChange(answer, nextId) {
  const status = $("#edit-status");
  const diff = $("#edit-diff");
  if (answer.status !== 200) {
    status.className = "result error";
    status.textContent = answer.data.error || `refused (${answer.status})`;
    diff.hidden = !answer.data.diff;
    diff.textContent = answer.data.diff || "";
    return;
  }
  status.className = "result";
  const rows = answer.data.summary.split("\n").slice(1).map((r) => r.trim());
  status.textContent = `Saved: ${rows.join("; ") || "nothing changed"}`;
  const next = answer.data.device;
  if (next === null) {
    location.hash = "#/devices";
    return;
  }
  page.route = "";  // the device restarted: its page afresh
  if (next !== undefined && `#/device/${encodeURIComponent(next)}` !== location.hash) {
    location.hash = `#/device/${encodeURIComponent(next)}`;
  } else {
    route();
  }
  showEdit(nextId).catch(() => {});
}

async function removeDevice() {
  const device = editing.device;
  const yes = await confirmStep(
    `Remove ${device.display_name} from the config? The bridge stops polling it and its ` +
      "entities leave Home Assistant (its discovery and retained state are cleared).",
    [], "Remove");
  if (!yes) return;
  afterChange(await apiAnswer(devicePath(device.id, "remove"), {}));
}

// An in-page confirmation (no window.confirm: it blocks the page): resolves true or false.
function confirmStep(question, items, yesText) {
  const box = $("#edit-confirm");
  $("#edit-confirm-question").textContent = question;
  $("#edit-confirm-list").replaceChildren(...items.map((item) => el("li", item)));
  $("#edit-confirm-list").hidden = !items.length;
  $("#edit-confirm-yes").textContent = yesText;
  box.hidden = false;
  $("#edit-confirm-no").focus();  // Enter alone never confirms
  return new Promise((resolve) => {
    editing.answer = (yes) => {
      editing.answer = null;
      box.hidden = true;
      resolve(yes);
    };
  });
}

// The confirmation closed: a question still open is answered no.
function hideConfirm() {
  if (editing.answer) editing.answer(false);
  $("#edit-confirm").hidden = true;
}

// --- devices not polled ------------------------------------------------------------------

async function showNotPolled() {
  const { status, data } = await apiAnswer("api/config/devices");
  const box = $("#not-polled");
  const off = status === 200 ? data.devices.filter((d) => !d.enabled) : [];
  box.hidden = !off.length;
  $("ul", box).replaceChildren(...off.map((d) => {
    const item = el("li", `${d.display_name} (${d.bus} / unit ${d.unit}) `);
    item.dataset.device = d.id;
    const button = el("button", "Enable");
    button.type = "button";
    button.setAttribute("aria-label", `Enable ${d.display_name}`);
    button.addEventListener("click", async () => {
      button.disabled = true;
      const answer = await apiAnswer(devicePath(d.id), { enabled: true });
      if (answer.status !== 200) item.append(el("span", ` ${answer.data.error}`, "error"));
      showNotPolled().catch(() => {});
    });
    item.append(button);
    return item;
  }));
}

function editRoute() {
  const [, name, id] = location.hash.match(/^#\/([a-z]+)(?:\/(.+))?/) || [];
  if (name === "device" && id) {
    const deviceId = decodeURIComponent(id);
    if (!editing.device || editing.device.id !== deviceId) showEdit(deviceId).catch(() => {});
  } else {
    editing.device = null;
    $("#edit").hidden = true;
  }
  if (!name || name === "devices") showNotPolled().catch(() => {});
}

function startEdit() {
  const form = $("#edit-form");
  form.addEventListener("submit", (e) => {
    e.preventDefault();
    run(form, $("#edit-status"), saveEdit);
  });
  $("#edit-remove").addEventListener("click", () => removeDevice().catch((error) => {
    $("#edit-status").textContent = error.message;
  }));
  $("#edit-confirm-yes").addEventListener("click", () => editing.answer && editing.answer(true));
  $("#edit-confirm-no").addEventListener("click", () => hideConfirm());
  window.addEventListener("hashchange", editRoute);
  editRoute();
}

startEdit();
