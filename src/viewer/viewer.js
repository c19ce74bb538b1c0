// stagelight's image viewer: decodes each image's float32 data, shows it tone-mapped or as a
// relative-error map in views that share one zoom and pan, and reads out linear RGB.
"use strict";
(function () {
  const manifest = JSON.parse(document.getElementById("manifest").textContent);
  const statusLine = document.getElementById("status");
  const reference = manifest.reference;
  const entries = [reference].concat(manifest.images);
  const width = reference.width;
  const height = reference.height;
  const floatsById = new Map();
  const relmseById = new Map();
  const errorMapById = new Map();

  function unique(list) {
    return list.filter((v, i) => list.indexOf(v) === i);
  }
  const groups = unique(manifest.images.map((e) => e.group));
  const imagesOfGroup = (group) => manifest.images.filter((e) => e.group === group);

  const view = {
    group: groups[0],
    method: manifest.images.length ? manifest.images[0].method : null,
    flipped: false,
    errorMode: false,
    exposure: 0,
    zoom: 1,
    centerX: width / 2,
    centerY: height / 2,
    hover: null,
  };

  function reportError(message) {
    window.stagelightErrors.push(message);
    statusLine.dataset.errors = window.stagelightErrors.length;
    statusLine.textContent = "Error: " + window.stagelightErrors.join("; ");
  }

  // ---- Decoding: base64, zlib (the browser's own inflate), bytes regrouped into floats.

  async function decodeFloats(entry, base64) {
    if (entry.format !== "f32-planes-zlib") {
      throw new Error(entry.id + ": unknown float format " + entry.format);
    }
    const packed = Uint8Array.from(atob(base64), (c) => c.charCodeAt(0));
    const stream = new Blob([packed]).stream().pipeThrough(new DecompressionStream("deflate"));
    const planes = new Uint8Array(await new Response(stream).arrayBuffer());
    const count = entry.width * entry.height;
    if (planes.length !== count * 12) {
      throw new Error(entry.id + ": " + planes.length + " bytes, not the " + count * 12 +
        " of " + entry.width + "x" + entry.height + " RGB floats");
    }
    const values = 3 * count;
    const bytes = new Uint8Array(values * 4);
    for (let b = 0; b < 4; b++) {
      const plane = planes.subarray(b * values, (b + 1) * values);
      for (let v = 0; v < values; v++) bytes[4 * v + b] = plane[v];
    }
    const planar = new Float32Array(bytes.buffer);
    const rgb = new Float32Array(values);
    for (let c = 0; c < 3; c++) {
      for (let i = 0; i < count; i++) rgb[3 * i + c] = planar[c * count + i];
    }
    return rgb;
  }

  const pending = new Map();
  window.stagelightImageData = function (id, base64) {
    const waiting = pending.get(id);
    if (!waiting) {
      reportError("image data for unknown image " + id);
      return;
    }
    pending.delete(id);
    decodeFloats(waiting.entry, base64).then(waiting.resolve, waiting.reject);
  };

  function loadImage(entry) {
    return new Promise((resolve, reject) => {
      pending.set(entry.id, { entry, resolve, reject });
      const script = document.createElement("script");
      script.src = entry.script;
      script.onerror = () => reject(new Error("could not load " + entry.script));
      document.body.appendChild(script);
    });
  }

  // ---- Error maps: per pixel the mean over RGB of (x - r)^2 / (r^2 + 0.01), as relMSE is.

  function errorMap(id) {
    if (errorMapById.has(id)) return errorMapById.get(id);
    const x = floatsById.get(id);
    const r = floatsById.get(reference.id);
    const map = new Float32Array(width * height);
    let sum = 0;
    for (let i = 0; i < map.length; i++) {
      let e = 0;
      for (let c = 0; c < 3; c++) {
        const d = x[3 * i + c] - r[3 * i + c];
        const rc = r[3 * i + c];
        e += (d * d) / (rc * rc + 0.01);
      }
      map[i] = e / 3;
      sum += e / 3;
    }
    errorMapById.set(id, map);
    relmseById.set(id, sum / map.length);
    return map;
  }

  // The error scale: five decades ending at the decade above the largest maps' 99.5th
  // percentile, so that a few fireflies do not wash out the rest.
  const errorScale = { low: -4, high: 1 };
  function chooseErrorScale() {
    let top = 0;
    const step = Math.max(1, Math.floor((width * height) / 20000));
    for (const entry of manifest.images) {
      const map = errorMap(entry.id);
      const sample = [];
      for (let i = 0; i < map.length; i += step) sample.push(map[i]);
      sample.sort((a, b) => a - b);
      top = Math.max(top, sample[Math.floor(0.995 * (sample.length - 1))] || 0);
    }
    if (top > 0 && isFinite(top)) {
      errorScale.high = Math.ceil(Math.log10(top));
      errorScale.low = errorScale.high - 5;
    }
  }

  // A dark-to-bright false-colour ramp (black, violet, red, orange, pale yellow).
  const rampStops = [
    [0.0, 4, 4, 16], [0.2, 60, 15, 110], [0.45, 170, 30, 100],
    [0.7, 240, 100, 30], [0.9, 252, 210, 70], [1.0, 255, 255, 230],
  ];
  function falseColour(t) {
    t = Math.min(1, Math.max(0, t));
    for (let k = 1; k < rampStops.length; k++) {
      const a = rampStops[k - 1];
      const b = rampStops[k];
      if (t <= b[0]) {
        const f = (t - a[0]) / (b[0] - a[0]);
        return [0, 1, 2].map((c) => Math.round(a[c + 1] + f * (b[c + 1] - a[c + 1])));
      }
    }
    return rampStops[rampStops.length - 1].slice(1);
  }
  const rampTable = Array.from({ length: 256 }, (_, i) => falseColour(i / 255));

  // ---- Tone mapping into 8-bit canvases, cached per image, mode and exposure.

  const srgbTable = new Uint8ClampedArray(4097);
  for (let i = 0; i <= 4096; i++) {
    const v = i / 4096;
    const s = v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055;
    srgbTable[i] = Math.round(255 * s);
  }
  const bitmaps = new Map();
  function bitmap(id, errorMode) {
    const key = id + (errorMode ? "|error" : "|" + view.exposure);
    if (bitmaps.has(key)) return bitmaps.get(key);
    const canvas = document.createElement("canvas");
    canvas.width = width;
    canvas.height = height;
    const context = canvas.getContext("2d");
    const pixels = context.createImageData(width, height);
    const out = pixels.data;
    if (errorMode) {
      const map = errorMap(id);
      const span = errorScale.high - errorScale.low;
      for (let i = 0; i < map.length; i++) {
        const t = map[i] > 0 ? (Math.log10(map[i]) - errorScale.low) / span : 0;
        const colour = rampTable[Math.min(255, Math.max(0, Math.round(t * 255)))];
        out[4 * i] = colour[0];
        out[4 * i + 1] = colour[1];
        out[4 * i + 2] = colour[2];
        out[4 * i + 3] = 255;
      }
    } else {
      const rgb = floatsById.get(id);
      const scale = Math.pow(2, view.exposure) * 4096;
      for (let i = 0; i < width * height; i++) {
        for (let c = 0; c < 3; c++) {
          const v = rgb[3 * i + c] * scale;
          // NaN and negatives show black; above 1 saturates.
          out[4 * i + c] = v > 0 ? srgbTable[v < 4096 ? v | 0 : 4096] : 0;
        }
        out[4 * i + 3] = 255;
      }
    }
    context.putImageData(pixels, 0, 0);
    bitmaps.set(key, canvas);
    return canvas;
  }
  function dropToneMapped() {
    for (const key of Array.from(bitmaps.keys())) {
      if (!key.endsWith("|error")) bitmaps.delete(key);
    }
  }

  // ---- Views: the main one and the side-by-side strip, all drawn with `view`'s zoom and pan.

  const panes = [];
  function entryOf(group, method) {
    return manifest.images.find((e) => e.group === group && e.method === method) || null;
  }
  function selectedEntry() {
    return entryOf(view.group, view.method) || imagesOfGroup(view.group)[0] || reference;
  }
  function labelOf(entry) {
    if (entry === reference) return "reference";
    return entry.group ? entry.method + " · " + entry.group : entry.method;
  }

  // The main view fills its place in the page; the strip's views are made here.
  function makePane(container, shownEntry, isMain) {
    const element = isMain ? container : document.createElement("div");
    if (!isMain) element.className = "pane";
    const canvas = document.createElement("canvas");
    const label = document.createElement("div");
    label.className = "label";
    element.append(canvas, label);
    if (!isMain) container.appendChild(element);
    const pane = { element, canvas, label, shownEntry, isMain };
    attachPointer(pane);
    panes.push(pane);
    return pane;
  }

  function drawPane(pane) {
    const entry = pane.shownEntry();
    const ratio = window.devicePixelRatio || 1;
    const cssWidth = pane.canvas.clientWidth;
    const cssHeight = pane.canvas.clientHeight;
    if (pane.canvas.width !== Math.round(cssWidth * ratio)) pane.canvas.width = Math.round(cssWidth * ratio);
    if (pane.canvas.height !== Math.round(cssHeight * ratio)) pane.canvas.height = Math.round(cssHeight * ratio);
    const context = pane.canvas.getContext("2d");
    context.setTransform(1, 0, 0, 1, 0, 0);
    context.fillStyle = "#0b0c0e";
    context.fillRect(0, 0, pane.canvas.width, pane.canvas.height);
    const relmse = relmseById.get(entry.id);
    pane.label.textContent = labelOf(entry) +
      (view.errorMode && entry !== reference ? " · error map" : "") +
      (relmse !== undefined && entry !== reference ? " · relMSE " + relmse.toExponential(3) : "");
    pane.element.dataset.image = entry.id;
    if (!floatsById.has(entry.id)) return;
    const zoom = view.zoom * ratio;
    const originX = (cssWidth / 2 - view.centerX * view.zoom) * ratio;
    const originY = (cssHeight / 2 - view.centerY * view.zoom) * ratio;
    context.setTransform(zoom, 0, 0, zoom, originX, originY);
    // Magnified pixels stay sharp squares; shrunk images are filtered.
    context.imageSmoothingEnabled = view.zoom < 1;
    const showError = view.errorMode && entry !== reference;
    context.drawImage(bitmap(entry.id, showError), 0, 0);
    if (view.hover && view.zoom >= 6) {
      context.lineWidth = 2 / zoom;
      context.strokeStyle = "#f0a640";
      context.strokeRect(view.hover.x, view.hover.y, 1, 1);
    }
  }
  function drawAll() {
    for (const pane of panes) drawPane(pane);
  }
  let drawQueued = false;
  function drawSoon() {
    if (drawQueued) return;
    drawQueued = true;
    requestAnimationFrame(() => {
      drawQueued = false;
      drawAll();
    });
  }

  // The image pixel under a point of a pane, in image coordinates (not rounded).
  function imagePoint(pane, clientX, clientY) {
    const box = pane.canvas.getBoundingClientRect();
    return {
      x: view.centerX + (clientX - box.left - box.width / 2) / view.zoom,
      y: view.centerY + (clientY - box.top - box.height / 2) / view.zoom,
    };
  }

  function zoomAbout(pane, clientX, clientY, factor) {
    const before = imagePoint(pane, clientX, clientY);
    view.zoom = Math.min(512, Math.max(1 / 64, view.zoom * factor));
    const after = imagePoint(pane, clientX, clientY);
    view.centerX += before.x - after.x;
    view.centerY += before.y - after.y;
    drawAll();
  }

  // One drag at a time, over whichever view it started in; the window follows it so that a
  // drag may leave the view.
  let drag = null;
  window.addEventListener("mousemove", (event) => {
    if (!drag) return;
    const dx = event.clientX - drag.x;
    const dy = event.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 0) drag.moved = true;
    view.centerX -= dx / view.zoom;
    view.centerY -= dy / view.zoom;
    drag.x = event.clientX;
    drag.y = event.clientY;
    drawSoon();
  });
  window.addEventListener("mouseup", () => {
    if (!drag) return;
    // A click (no drag) on a side-by-side view picks its method.
    if (!drag.moved && !drag.pane.isMain) {
      const entry = drag.pane.shownEntry();
      if (entry !== reference) selectMethod(entry.method);
    }
    drag.pane.element.classList.remove("dragging");
    drag = null;
  });

  function attachPointer(pane) {
    pane.canvas.addEventListener("wheel", (event) => {
      event.preventDefault();
      const lines = event.deltaMode === 1 ? 40 : event.deltaMode === 2 ? 400 : 1;
      zoomAbout(pane, event.clientX, event.clientY, Math.exp(-event.deltaY * lines * 0.002));
    }, { passive: false });
    pane.canvas.addEventListener("mousedown", (event) => {
      drag = { pane, x: event.clientX, y: event.clientY, moved: false };
      pane.element.classList.add("dragging");
    });
    pane.canvas.addEventListener("mousemove", (event) => {
      const point = imagePoint(pane, event.clientX, event.clientY);
      const x = Math.floor(point.x);
      const y = Math.floor(point.y);
      if (x < 0 || y < 0 || x >= width || y >= height) return;
      view.hover = { x, y };
      showReadout(pane.shownEntry(), x, y);
      drawSoon();
    });
  }

  // ---- Pixel readout: the floats as the shortest decimals that read back as the same float32.

  function float32Text(value) {
    if (!isFinite(value)) return String(value);
    for (let digits = 1; digits < 10; digits++) {
      const text = value.toPrecision(digits);
      if (Math.fround(parseFloat(text)) === value) return String(parseFloat(text));
    }
    return String(value);
  }
  const readout = document.getElementById("readout");
  function showReadout(entry, x, y) {
    const rgb = floatsById.get(entry.id);
    const ref = floatsById.get(reference.id);
    if (!rgb || !ref) return;
    const i = 3 * (y * width + x);
    const values = [rgb[i], rgb[i + 1], rgb[i + 2]].map(float32Text);
    const refValues = [ref[i], ref[i + 1], ref[i + 2]].map(float32Text);
    const lines = [
      "pixel      x " + x + "  y " + y,
      "image      " + labelOf(entry),
      "linear RGB " + values.join("  "),
    ];
    if (entry !== reference) {
      lines.push("reference  " + refValues.join("  "));
      lines.push("rel. sq. error " + errorMap(entry.id)[y * width + x].toExponential(3));
    }
    readout.textContent = lines.join("\n");
    Object.assign(readout.dataset, { x, y, image: entry.id, rgb: values.join(" ") });
  }

  // ---- Controls.

  const groupSelect = document.getElementById("group-select");
  const methodSelect = document.getElementById("method-select");
  const flipButton = document.getElementById("flip-button");
  const errorButton = document.getElementById("error-button");
  const exposureInput = document.getElementById("exposure");
  const exposureValue = document.getElementById("exposure-value");
  const stripTitle = document.getElementById("strip-title");
  const strip = document.getElementById("strip");
  const mainPane = makePane(document.getElementById("main-pane"),
    () => (view.flipped ? reference : selectedEntry()), true);

  function fillSelect(select, values, chosen) {
    select.replaceChildren(...values.map((v) => {
      const option = document.createElement("option");
      option.value = v;
      option.textContent = v || "(all)";
      option.selected = v === chosen;
      return option;
    }));
  }

  function rebuildStrip() {
    for (let k = panes.length - 1; k >= 0; k--) {
      if (!panes[k].isMain) panes.splice(k, 1);
    }
    strip.replaceChildren();
    for (const entry of imagesOfGroup(view.group).concat([reference])) {
      makePane(strip, () => entry, false);
    }
    stripTitle.textContent = view.group
      ? "Every method at " + view.group + ", and the reference"
      : "Every image, and the reference";
  }

  function syncControls() {
    fillSelect(groupSelect, groups, view.group);
    groupSelect.parentElement.hidden = groups.length < 2 && !groups[0];
    fillSelect(methodSelect, imagesOfGroup(view.group).map((e) => e.method), selectedEntry().method);
    flipButton.setAttribute("aria-pressed", String(view.flipped));
    errorButton.setAttribute("aria-pressed", String(view.errorMode));
    mainPane.element.classList.toggle("flipped", view.flipped);
    for (const pane of panes) {
      if (!pane.isMain) pane.element.classList.toggle("selected", pane.shownEntry() === selectedEntry());
    }
    for (const row of document.querySelectorAll("#results-table tbody tr")) {
      row.classList.toggle("current", row.dataset.image === selectedEntry().id);
    }
  }

  function selectGroup(group) {
    view.group = group;
    if (!entryOf(group, view.method)) view.method = imagesOfGroup(group)[0].method;
    rebuildStrip();
    syncControls();
    drawAll();
  }
  function selectMethod(method) {
    view.method = method;
    syncControls();
    drawAll();
  }
  function setFlipped(flipped) {
    view.flipped = flipped;
    syncControls();
    drawAll();
  }
  function setErrorMode(on) {
    view.errorMode = on;
    syncControls();
    drawAll();
  }
  function fit() {
    const box = mainPane.canvas.getBoundingClientRect();
    view.zoom = Math.min(box.width / width, box.height / height) || 1;
    view.centerX = width / 2;
    view.centerY = height / 2;
    drawAll();
  }
  function zoomAtCentre(factor) {
    const box = mainPane.canvas.getBoundingClientRect();
    zoomAbout(mainPane, box.left + box.width / 2, box.top + box.height / 2, factor);
  }
  function stepMethod(step) {
    const methods = imagesOfGroup(view.group).map((e) => e.method);
    const k = methods.indexOf(selectedEntry().method);
    selectMethod(methods[(k + step + methods.length) % methods.length]);
  }

  groupSelect.addEventListener("change", () => selectGroup(groupSelect.value));
  methodSelect.addEventListener("change", () => selectMethod(methodSelect.value));
  flipButton.addEventListener("click", () => setFlipped(!view.flipped));
  errorButton.addEventListener("click", () => setErrorMode(!view.errorMode));
  exposureInput.addEventListener("input", () => {
    view.exposure = parseFloat(exposureInput.value);
    exposureValue.textContent = (view.exposure >= 0 ? "+" : "") + view.exposure.toFixed(1) + " EV";
    dropToneMapped();
    drawAll();
  });
  document.getElementById("fit-button").addEventListener("click", fit);
  document.getElementById("actual-button").addEventListener("click", () => {
    view.zoom = 1 / (window.devicePixelRatio || 1);
    drawAll();
  });
  document.addEventListener("keydown", (event) => {
    const target = event.target;
    if (event.ctrlKey || event.metaKey || event.altKey) return;
    if (target && (target.tagName === "SELECT" || (target.tagName === "INPUT" && target.type !== "range"))) return;
    const actions = {
      f: () => setFlipped(!view.flipped),
      e: () => setErrorMode(!view.errorMode),
      0: fit,
      1: () => { view.zoom = 1 / (window.devicePixelRatio || 1); drawAll(); },
      "+": () => zoomAtCentre(2),
      "=": () => zoomAtCentre(2),
      "-": () => zoomAtCentre(0.5),
      "[": () => stepMethod(-1),
      "]": () => stepMethod(1),
    };
    const action = actions[event.key.toLowerCase()];
    if (action) {
      event.preventDefault();
      action();
    }
  });
  window.addEventListener("resize", drawSoon);

  // ---- The error scale's legend.

  function drawErrorLegend() {
    const box = document.getElementById("error-scale");
    const canvas = document.createElement("canvas");
    canvas.width = 256;
    canvas.height = 1;
    const context = canvas.getContext("2d");
    const row = context.createImageData(256, 1);
    for (let i = 0; i < 256; i++) {
      row.data.set(rampTable[i].concat([255]), 4 * i);
    }
    context.putImageData(row, 0, 0);
    const ticks = document.createElement("div");
    ticks.className = "ticks";
    for (let d = errorScale.low; d <= errorScale.high; d++) {
      const tick = document.createElement("span");
      tick.textContent = "1e" + d;
      ticks.appendChild(tick);
    }
    const title = document.createElement("div");
    title.textContent = "Error map (E): relative squared error (x − r)² / (r² + 0.01), mean over RGB, log scale; black: at most 1e" + errorScale.low + ".";
    box.replaceChildren(title, canvas, ticks);
    box.dataset.low = errorScale.low;
    box.dataset.high = errorScale.high;
  }

  // ---- The results table, sortable by any column.

  function buildTable() {
    const table = document.getElementById("results-table");
    if (!table || !manifest.table) return;
    const head = document.createElement("thead");
    const headRow = document.createElement("tr");
    const body = document.createElement("tbody");
    const rows = manifest.table.rows.map((row) => {
      const tr = document.createElement("tr");
      for (const cell of row.cells) {
        const td = document.createElement("td");
        td.textContent = cell.text;
        tr.appendChild(td);
      }
      if (row.image !== null && row.image !== undefined) {
        const entry = manifest.images[row.image];
        tr.dataset.image = entry.id;
        tr.addEventListener("click", () => {
          view.flipped = false;
          if (view.group !== entry.group) {
            view.method = entry.method;
            selectGroup(entry.group);
          } else {
            selectMethod(entry.method);
          }
          document.getElementById("viewer").scrollIntoView({ behavior: "smooth" });
        });
      }
      return { row, tr };
    });
    manifest.table.columns.forEach((name, column) => {
      const th = document.createElement("th");
      th.textContent = name;
      th.addEventListener("click", () => {
        const ascending = th.getAttribute("aria-sort") !== "ascending";
        for (const other of headRow.children) other.removeAttribute("aria-sort");
        th.setAttribute("aria-sort", ascending ? "ascending" : "descending");
        const key = (r) => r.row.cells[column];
        rows.sort((a, b) => {
          const x = key(a);
          const y = key(b);
          const order = x.value !== null && y.value !== null
            ? x.value - y.value
            : x.text.localeCompare(y.text, undefined, { numeric: true });
          return ascending ? order : -order;
        });
        body.replaceChildren(...rows.map((r) => r.tr));
      });
      headRow.appendChild(th);
    });
    head.appendChild(headRow);
    body.replaceChildren(...rows.map((r) => r.tr));
    table.replaceChildren(head, body);
  }

  // ---- Start: load every image, then show the first.

  fillSelect(groupSelect, groups, view.group);
  rebuildStrip();
  syncControls();
  buildTable();
  drawAll();
  Promise.all(entries.map((entry) => loadImage(entry).then((rgb) => {
    floatsById.set(entry.id, rgb);
    statusLine.textContent = "Loading images… " + floatsById.size + " of " + entries.length;
  }))).then(() => {
    chooseErrorScale();
    drawErrorLegend();
    fit();
    syncControls();
    const runs = manifest.images.length;
    statusLine.textContent = runs + (runs === 1 ? " image" : " images") + " and the reference, " +
      width + "×" + height + ", decoded from their float32 data." +
      (window.stagelightErrors.length ? " Errors: " + window.stagelightErrors.join("; ") : "");
    statusLine.dataset.decoded = floatsById.size;
    // From navigation to every image decoded and drawn.
    statusLine.dataset.loadMs = Math.round(performance.now());
    statusLine.title = "loaded in " + Math.round(performance.now()) + " ms";
    statusLine.dataset.ready = "1";
    if (new URLSearchParams(location.search).has("selftest")) runSelfTest();
    else if (new URLSearchParams(location.search).has("demo")) demo();
  }).catch((error) => reportError(String(error && error.message ? error.message : error)));

  // ---- A state to show (?demo=ZOOM, with group, method, exposure, error=1, flip=1): the
  // browser test's screenshot and the README's.

  function demo() {
    const params = new URLSearchParams(location.search);
    const group = params.get("group");
    if (group !== null && groups.includes(group)) selectGroup(group);
    if (params.has("method")) selectMethod(params.get("method"));
    if (params.has("exposure")) {
      exposureInput.value = params.get("exposure");
      exposureInput.dispatchEvent(new Event("input"));
    }
    if (params.get("error") === "1") setErrorMode(true);
    if (params.get("flip") === "1") setFlipped(true);
    zoomAtCentre(parseFloat(params.get("demo")) || 2);
    const box = mainPane.canvas.getBoundingClientRect();
    mainPane.canvas.dispatchEvent(new MouseEvent("mousemove", {
      clientX: box.left + box.width * 0.55, clientY: box.top + box.height * 0.6, bubbles: true,
    }));
    drawAll();
  }

  // ---- Self-test (?selftest=x,y;x,y;...): drives the page as a user would and writes what
  // it saw into #selftest, for the browser test to compare with the EXRs.

  function canvasDigest(canvas) {
    const data = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
    let hash = 2166136261;
    const colours = new Set();
    for (let i = 0; i < data.length; i += 4) {
      const pixel = (data[i] << 16) | (data[i + 1] << 8) | data[i + 2];
      hash = Math.imul(hash ^ pixel, 16777619) >>> 0;
      if (colours.size < 5000) colours.add(pixel);
    }
    return { hash, colours: colours.size };
  }
  function hoverMain(x, y) {
    const box = mainPane.canvas.getBoundingClientRect();
    mainPane.canvas.dispatchEvent(new MouseEvent("mousemove", {
      clientX: box.left + box.width / 2 + (x + 0.5 - view.centerX) * view.zoom,
      clientY: box.top + box.height / 2 + (y + 0.5 - view.centerY) * view.zoom,
      bubbles: true,
    }));
    return { x: Number(readout.dataset.x), y: Number(readout.dataset.y), image: readout.dataset.image, rgb: readout.dataset.rgb };
  }
  function press(key) {
    document.dispatchEvent(new KeyboardEvent("keydown", { key, bubbles: true }));
  }

  function runSelfTest() {
    const result = {};
    const probes = new URLSearchParams(location.search).get("selftest").split(";")
      .filter((p) => p).map((p) => p.split(",").map(Number));
    selectGroup(groups[0]);
    selectMethod(imagesOfGroup(groups[0])[0].method);
    fit();
    result.shown = selectedEntry().id;
    result.probes = probes.map(([x, y]) => hoverMain(x, y));
    const image = canvasDigest(mainPane.canvas);
    press("f");
    const flipped = canvasDigest(mainPane.canvas);
    result.flip = {
      image, flipped, shownWhenFlipped: mainPane.element.dataset.image,
      probeWhenFlipped: probes.length ? hoverMain(probes[0][0], probes[0][1]) : null,
    };
    flipButton.click();
    result.flip.back = canvasDigest(mainPane.canvas);
    result.flip.shownAfterButton = mainPane.element.dataset.image;
    press("e");
    result.errorMap = { digest: canvasDigest(mainPane.canvas), label: mainPane.label.textContent };
    press("e");
    exposureInput.value = "3";
    exposureInput.dispatchEvent(new Event("input"));
    result.exposure = { digest: canvasDigest(mainPane.canvas), shown: exposureValue.textContent };
    exposureInput.value = "0";
    exposureInput.dispatchEvent(new Event("input"));
    const zoomBefore = view.zoom;
    const box = mainPane.canvas.getBoundingClientRect();
    mainPane.canvas.dispatchEvent(new WheelEvent("wheel", {
      deltaY: -600, clientX: box.left + box.width / 2, clientY: box.top + box.height / 2,
      bubbles: true, cancelable: true,
    }));
    result.zoom = {
      before: zoomBefore, after: view.zoom,
      // Every view draws one zoom and centre: the same image pixel sits at each view's centre.
      centres: panes.map((pane) => {
        const b = pane.canvas.getBoundingClientRect();
        const p = imagePoint(pane, b.left + b.width / 2, b.top + b.height / 2);
        return [Math.floor(p.x), Math.floor(p.y)];
      }),
      strip: panes.filter((p) => !p.isMain).map((p) => p.element.dataset.image),
    };
    // A drag pans every view; a click on a side-by-side view shows its method.
    const centreBefore = [view.centerX, view.centerY];
    mainPane.canvas.dispatchEvent(new MouseEvent("mousedown", { clientX: 300, clientY: 300, bubbles: true }));
    window.dispatchEvent(new MouseEvent("mousemove", { clientX: 340, clientY: 320 }));
    window.dispatchEvent(new MouseEvent("mouseup", {}));
    result.pan = { zoom: view.zoom, before: centreBefore, after: [view.centerX, view.centerY] };
    const second = panes.filter((p) => !p.isMain)[1];
    second.canvas.dispatchEvent(new MouseEvent("mousedown", { clientX: 5, clientY: 5, bubbles: true }));
    window.dispatchEvent(new MouseEvent("mouseup", {}));
    result.stripClick = { clicked: second.element.dataset.image, shown: mainPane.element.dataset.image };
    selectMethod(imagesOfGroup(groups[0])[0].method);
    fit();
    const th = Array.from(document.querySelectorAll("#results-table th"));
    const relmseColumn = th.findIndex((h) => h.textContent.startsWith("relMSE"));
    if (relmseColumn >= 0) {
      th[relmseColumn].click();
      result.sortedRelmse = Array.from(document.querySelectorAll("#results-table tbody tr"))
        .map((tr) => tr.children[relmseColumn].textContent);
    }
    result.images = entries.map((e) => ({
      id: e.id, method: e.method, group: e.group, values: floatsById.get(e.id).length,
      relmse: e === reference ? 0 : relmseById.get(e.id),
    }));
    result.errorScale = [errorScale.low, errorScale.high];
    result.errors = window.stagelightErrors.slice();
    const out = document.getElementById("selftest");
    out.textContent = JSON.stringify(result);
    out.dataset.done = "1";
  }
})();
