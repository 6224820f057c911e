// The farm's dashboard: polls state.json (relative to the page, so under
// its token) once a second and redraws the tables. Every string from the
// farm (users, scene names, errors: anyone who may submit chooses them)
// goes into the page as text (textContent), never as markup.
"use strict";

const POLL_MS = 1000;

function el(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined && text !== null) e.textContent = String(text);
  if (cls) e.className = cls;
  return e;
}

function row(cells) {
  const tr = document.createElement("tr");
  for (const c of cells) tr.appendChild(c);
  return tr;
}

function duration(ms) {
  if (ms === null || ms === undefined) return "–";
  let s = Math.round(ms / 1000);
  if (s < 60) return s + " s";
  const m = Math.floor(s / 60);
  s = s % 60;
  if (m < 60) return m + " min " + s + " s";
  return Math.floor(m / 60) + " h " + (m % 60) + " min";
}

// Only the preview's own kind of address becomes a link.
function safeLink(url) {
  return typeof url === "string" && /^http:\/\/[0-9a-zA-Z.:\[\]-]+\/[A-Za-z0-9_-]+\/$/.test(url);
}

function workers(list) {
  const body = document.querySelector("#workers tbody");
  body.replaceChildren(...list.map((w) => {
    const tr = row([
      el("td", w.node, "name node"),
      el("td", w.state, "name state-" + w.state),
      el("td", w.job === null ? "–" : "#" + w.job),
      el("td", w.speed === 1 ? "1" : "1/" + w.speed),
      el("td", w.slots),
      el("td", w.tags.join(", "), "name"),
    ]);
    tr.className = "worker";
    return tr;
  }));
  document.getElementById("noworkers").hidden = list.length > 0;
  document.getElementById("workercount").textContent =
    list.length + " joined, " + list.filter((w) => w.state === "working").length + " working";
}

function progress(j) {
  const td = el("td", undefined, "name");
  const bar = el("span", undefined, "bar");
  const fill = el("span");
  fill.style.width = Math.round(100 * j.progress) + "%";
  bar.appendChild(fill);
  td.appendChild(bar);
  td.appendChild(document.createTextNode(Math.floor(100 * j.progress) + "%"));
  if (j.error) td.appendChild(el("div", j.error, "error"));
  return td;
}

function preview(j) {
  const td = el("td", undefined, "name");
  if (j.state === "running" && safeLink(j.preview)) {
    const a = el("a", "live preview", "preview");
    a.href = j.preview;
    a.target = "_blank";
    a.rel = "noopener noreferrer";
    td.appendChild(a);
  } else {
    td.textContent = "–";
  }
  return td;
}

function jobs(list, omitted) {
  const body = document.querySelector("#jobs tbody");
  body.replaceChildren(...list.map((j) => {
    const tr = row([
      el("td", j.id),
      el("td", j.user, "name user"),
      el("td", j.scene, "name scene"),
      el("td", j.state, "name state-" + j.state),
      el("td", j.priority),
      el("td", j.done + " / " + j.frames, "frames"),
      progress(j),
      el("td", j.state === "running" ? duration(j.time_left) : "–", "left"),
      el("td", j.workers.join(", "), "name"),
      preview(j),
    ]);
    tr.className = "job";
    tr.dataset.id = j.id;
    return tr;
  }));
  document.getElementById("nojobs").hidden = list.length > 0;
  document.getElementById("ended").textContent =
    omitted > 0 ? "(" + omitted + " older ended jobs not shown)" : "";
}

function queue(ids) {
  const q = document.getElementById("queue");
  if (ids.length === 0) {
    q.textContent = "empty";
  } else {
    q.replaceChildren(...ids.map((id) => el("span", "#" + id, "chip")));
  }
}

function show(view) {
  workers(view.workers);
  jobs(view.jobs, view.ended_omitted);
  queue(view.queue);
  document.getElementById("status").textContent =
    "head " + view.head + " · updated " + new Date(view.now).toLocaleTimeString();
  document.body.dataset.state = "live";
  document.body.dataset.updates = String(+(document.body.dataset.updates || 0) + 1);
}

async function poll() {
  try {
    const response = await fetch("state.json", { cache: "no-store" });
    if (!response.ok) throw new Error("HTTP " + response.status);
    show(await response.json());
  } catch (e) {
    document.body.dataset.state = "stale";
    document.getElementById("status").textContent = "the head does not answer (" + e.message + "); trying again";
  }
  setTimeout(poll, POLL_MS);
}

poll();
