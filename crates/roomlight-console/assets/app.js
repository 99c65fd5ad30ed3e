// roomlight console: the installer's page. It reads the camera agent's JSON API
// (docs/console.md), follows the room over Server-Sent Events, edits the survey and starts
// calibrations. No framework and no build step: the camera agent embeds this file as it is.
// Everything shown from the room is set as text (never as HTML).
'use strict';

const $ = (id) => document.getElementById(id);
const PAGES = ['room', 'survey', 'calibration'];
// How many rounds the plots keep, as /api/history does.
const HISTORY_LIMIT = 2000;
const THUMBNAIL_MS = 3000;

/// Everything the page knows, updated by the API's answers and the status events.
const state = {
  csrf: '',
  page: 'room',
  status: null,
  /// {round, captures, t, objective, excess}, oldest first.
  history: [],
  /// The agent's clock (`t`, seconds since it started) minus this page's clock, estimated when
  /// the history was read: status events carry no `t`, their points are placed with it.
  clockOffset: null,
  imageSeq: null,
  /// {version, survey} as last read or saved; null when the agent runs without a survey.
  survey: null,
  /// The survey being edited (a copy of state.survey.survey).
  draft: null,
  dirty: false,
  /// 'none', 'chart' (clicking four corners), 'naming' (waiting for the name) or 'target'.
  mode: 'none',
  points: [],
  /// Per projector, what its calibration images were last loaded for.
  calibrationKeys: new Map(),
  redrawQueued: false,
};

// ---- small helpers ------------------------------------------------------------------------

function element(tag, props = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(props)) {
    if (key === 'dataset') Object.assign(node.dataset, value);
    else if (key in node) node[key] = value;
    else node.setAttribute(key, value);
  }
  node.append(...children);
  return node;
}

function setText(node, text) {
  const value = String(text);
  if (node.textContent !== value) node.textContent = value;
}

function formatNumber(value) {
  if (value == null || !Number.isFinite(value)) return '–';
  if (value === 0) return '0';
  return Math.abs(value) >= 0.01 && Math.abs(value) < 1000 ? value.toPrecision(4) : value.toExponential(3);
}

/// `excess` is relative to the optimum (0.01 is 1% above G*).
function formatExcess(value) {
  return value == null ? '–' : `${(value * 100).toFixed(3)}%`;
}

let flashTimer = null;
function flash(message, bad = false) {
  const box = $('flash');
  box.textContent = message;
  box.classList.toggle('bad', bad);
  box.hidden = false;
  clearTimeout(flashTimer);
  flashTimer = setTimeout(() => { box.hidden = true; }, bad ? 8000 : 4000);
}

function errorText(answer) {
  const body = answer.data;
  if (body && body.error) {
    return body.item == null ? body.error : `${body.error} (${JSON.stringify(body.item)})`;
  }
  return `HTTP ${answer.status}`;
}

/// One request to the API: JSON in and out, the CSRF header on every state-changing request,
/// and back to the login page when the session has ended.
async function api(method, path, body) {
  const headers = {};
  if (method !== 'GET') headers['X-Roomlight-CSRF'] = state.csrf;
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  const response = await fetch(path, {
    method,
    headers,
    body: body === undefined ? undefined : JSON.stringify(body),
    credentials: 'same-origin',
    cache: 'no-store',
  });
  if (response.status === 401) {
    location.assign('/login');
    throw new Error('not logged in');
  }
  let data = null;
  if ((response.headers.get('content-type') || '').includes('json')) {
    data = await response.json().catch(() => null);
  }
  return { status: response.status, ok: response.ok, data };
}

/// Runs an action of a button; a failure is shown instead of lost.
function action(run) {
  return async (event) => {
    const button = event && event.currentTarget;
    if (button instanceof HTMLButtonElement) button.disabled = true;
    try {
      await run(event);
    } catch (error) {
      if (error.message !== 'not logged in') flash(`failed: ${error.message}`, true);
    } finally {
      if (button instanceof HTMLButtonElement) button.disabled = false;
      updateSurveyControls();
    }
  };
}

// ---- pages --------------------------------------------------------------------------------

function route() {
  const wanted = location.hash.slice(1);
  state.page = PAGES.includes(wanted) ? wanted : 'room';
  for (const page of PAGES) {
    $(`page-${page}`).hidden = page !== state.page;
  }
  for (const link of document.querySelectorAll('.tabs a')) {
    const active = link.dataset.page === state.page;
    link.classList.toggle('active', active);
    if (active) link.setAttribute('aria-current', 'page');
    else link.removeAttribute('aria-current');
  }
  if (state.page === 'room') refreshThumbnails();
  scheduleRedraw();
}

/// Canvases are drawn at most once a frame, and only those on the page shown.
function scheduleRedraw() {
  if (state.redrawQueued) return;
  state.redrawQueued = true;
  requestAnimationFrame(() => {
    state.redrawQueued = false;
    if (state.page === 'room') {
      drawOverlay($('room-overlay'), state.survey && state.survey.survey, null);
      drawPlot($('objective-plot'), 'round');
      drawPlot($('objective-time'), 't');
    } else if (state.page === 'survey') {
      drawOverlay($('survey-overlay'), state.draft, state.points);
    }
  });
}

/// A canvas sized to its box in device pixels; the context draws in CSS pixels.
function fitCanvas(canvas) {
  const width = canvas.clientWidth;
  const height = canvas.clientHeight;
  const ratio = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(width * ratio));
  const h = Math.max(1, Math.round(height * ratio));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
  const g = canvas.getContext('2d');
  g.setTransform(ratio, 0, 0, ratio, 0, 0);
  g.clearRect(0, 0, width, height);
  return { g, width, height };
}

// ---- the camera image and its overlay -----------------------------------------------------

function currentSurvey() {
  return state.draft || (state.survey && state.survey.survey);
}

/// The full camera image's size: the survey's coordinates and the API's are in its pixels.
function cameraSize() {
  const survey = currentSurvey();
  if (survey && survey.camera_width > 0 && survey.camera_height > 0) {
    return [survey.camera_width, survey.camera_height];
  }
  const image = state.status && state.status.image;
  if (image && image.width > 0 && image.height > 0) return [image.width, image.height];
  return [640, 480];
}

function setStageAspect() {
  const [w, h] = cameraSize();
  for (const stage of document.querySelectorAll('.stage')) {
    const aspect = `${w} / ${h}`;
    if (stage.style.aspectRatio !== aspect) stage.style.aspectRatio = aspect;
  }
}

function loadImages(seq) {
  state.imageSeq = seq;
  const url = `/api/image.png?seq=${encodeURIComponent(seq)}`;
  for (const id of ['camera-image', 'survey-image']) $(id).src = url;
}

function watchImage(img) {
  const stage = img.parentElement;
  img.addEventListener('load', () => {
    img.classList.remove('missing');
    stage.classList.remove('no-image');
  });
  img.addEventListener('error', () => {
    img.classList.add('missing');
    stage.classList.add('no-image');
  });
}

/// A survey whose target came as pixels only (`roomlight calibrate --survey-only`) is drawn
/// from its mask, /api/survey/target.png (white: target), tinted; loaded once a version.
const targetMask = { version: '', tinted: null };

function maskOf(survey) {
  if (!survey || !state.survey || (survey.target || []).length || !survey.target_pixels) return null;
  const version = state.survey.version;
  if (targetMask.version !== version) {
    targetMask.version = version;
    targetMask.tinted = null;
    const img = new Image();
    img.addEventListener('load', () => {
      const tinted = element('canvas', { width: img.naturalWidth, height: img.naturalHeight });
      const g = tinted.getContext('2d');
      g.drawImage(img, 0, 0);
      // The mask's brightness becomes the target colour's opacity: nothing over the rest.
      const pixels = g.getImageData(0, 0, tinted.width, tinted.height);
      const p = pixels.data;
      for (let i = 0; i < p.length; i += 4) {
        const alpha = p[i] * 0.6;
        p.set([255, 107, 107, alpha], i);
      }
      g.putImageData(pixels, 0, 0);
      targetMask.tinted = tinted;
      scheduleRedraw();
    });
    img.src = `/api/survey/target.png?v=${encodeURIComponent(version)}`;
  }
  return targetMask.tinted;
}

/// Charts as outlines (their top-left corner marked), the target filled (its polygons, or its
/// mask), and while editing the points clicked so far.
function drawOverlay(canvas, survey, points) {
  const { g, width, height } = fitCanvas(canvas);
  const mask = maskOf(survey);
  if (mask) g.drawImage(mask, 0, 0, width, height);
  const [cw, ch] = cameraSize();
  const sx = width / cw;
  const sy = height / ch;
  const trace = (corners, close) => {
    g.beginPath();
    corners.forEach(([x, y], k) => (k ? g.lineTo(x * sx, y * sy) : g.moveTo(x * sx, y * sy)));
    if (close) g.closePath();
  };
  g.lineWidth = 2;
  g.font = '600 12px system-ui, sans-serif';
  if (survey) {
    g.strokeStyle = '#ff6b6b';
    g.fillStyle = 'rgba(255, 107, 107, 0.28)';
    for (const polygon of survey.target || []) {
      if (polygon.length < 2) continue;
      trace(polygon, true);
      g.fill();
      g.stroke();
    }
    for (const chart of survey.charts || []) {
      g.strokeStyle = '#5ec8ff';
      trace(chart.corners, true);
      g.stroke();
      const [x, y] = chart.corners[0];
      g.fillStyle = '#5ec8ff';
      g.fillRect(x * sx - 3, y * sy - 3, 6, 6);
      g.fillText(chart.name, x * sx + 5, y * sy - 5);
    }
  }
  if (points && points.length) {
    const colour = state.mode === 'target' ? '#ffb86b' : '#9be7ff';
    g.strokeStyle = colour;
    g.fillStyle = colour;
    g.setLineDash([5, 4]);
    trace(points, state.mode === 'naming');
    g.stroke();
    g.setLineDash([]);
    points.forEach(([x, y], k) => {
      g.beginPath();
      g.arc(x * sx, y * sy, 4, 0, 2 * Math.PI);
      g.fill();
      if (state.mode !== 'target') g.fillText(['TL', 'TR', 'BR', 'BL'][k], x * sx + 6, y * sy + 14);
    });
  }
}

// ---- the objective plots ------------------------------------------------------------------

/// A step of 1, 2 or 5 times a power of ten giving about `count` ticks over `span`.
function niceStep(span, count) {
  const raw = span / count;
  const power = 10 ** Math.floor(Math.log10(raw));
  const unit = raw / power;
  return power * (unit < 1.5 ? 1 : unit < 3.5 ? 2 : unit < 7.5 ? 5 : 10);
}

/// The objective of every round in the history against `key` ('round' or 't'), log-scale y;
/// the optimum, when known, as a dashed line.
function drawPlot(canvas, key) {
  const { g, width, height } = fitCanvas(canvas);
  if (width < 10) return;
  const points = state.history.filter((p) => p.objective > 0 && Number.isFinite(p[key]));
  const optimum = state.status && state.status.optimum;
  const margin = { left: 54, right: 12, top: 10, bottom: 24 };
  g.font = '11px system-ui, sans-serif';
  g.fillStyle = '#97a0b0';
  if (!points.length) {
    g.fillText('no rounds yet', margin.left, height / 2);
    return;
  }
  const values = points.map((p) => p.objective);
  if (optimum > 0) values.push(optimum);
  let low = Math.floor(Math.log10(Math.min(...values)));
  let high = Math.ceil(Math.log10(Math.max(...values)));
  if (high <= low) high = low + 1;
  const x0 = points[0][key];
  let x1 = points[points.length - 1][key];
  if (x1 <= x0) x1 = x0 + 1;
  const plotW = width - margin.left - margin.right;
  const plotH = height - margin.top - margin.bottom;
  const X = (x) => margin.left + ((x - x0) / (x1 - x0)) * plotW;
  const Y = (v) => margin.top + plotH - ((Math.log10(v) - low) / (high - low)) * plotH;
  // Grid: one line a decade (fewer when there are many), ticks 1-2-5 along x.
  g.strokeStyle = '#2d3440';
  g.lineWidth = 1;
  const decades = Math.max(1, Math.ceil((high - low) / 6));
  g.textAlign = 'right';
  g.textBaseline = 'middle';
  for (let e = low; e <= high; e += decades) {
    const y = Math.round(Y(10 ** e)) + 0.5;
    g.beginPath();
    g.moveTo(margin.left, y);
    g.lineTo(width - margin.right, y);
    g.stroke();
    g.fillText(`1e${e}`, margin.left - 6, y);
  }
  g.textAlign = 'center';
  g.textBaseline = 'top';
  // Rounds are whole numbers: no tick between two.
  const step = Math.max(key === 'round' ? 1 : 0, niceStep(x1 - x0, Math.max(2, Math.floor(plotW / 90))));
  for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) {
    const px = Math.round(X(x)) + 0.5;
    g.beginPath();
    g.moveTo(px, margin.top);
    g.lineTo(px, margin.top + plotH);
    g.stroke();
    g.fillText(key === 't' ? `${+x.toFixed(1)}` : `${Math.round(x)}`, px, margin.top + plotH + 6);
  }
  if (optimum > 0) {
    g.strokeStyle = '#4ade80';
    g.setLineDash([6, 4]);
    g.beginPath();
    g.moveTo(margin.left, Y(optimum));
    g.lineTo(width - margin.right, Y(optimum));
    g.stroke();
    g.setLineDash([]);
  }
  g.strokeStyle = '#5ec8ff';
  g.lineWidth = 1.5;
  g.beginPath();
  points.forEach((p, k) => (k ? g.lineTo(X(p[key]), Y(p.objective)) : g.moveTo(X(p[key]), Y(p.objective))));
  g.stroke();
  const last = points[points.length - 1];
  g.fillStyle = '#5ec8ff';
  g.beginPath();
  g.arc(X(last[key]), Y(last.objective), 3, 0, 2 * Math.PI);
  g.fill();
}

/// Since the rounds last restarted: a round number that does not increase starts them anew.
function sinceRestart(points) {
  let start = 0;
  for (let k = 1; k < points.length; k += 1) if (points[k].round <= points[k - 1].round) start = k;
  return points.slice(start);
}

let historyLoading = null;
function loadHistory() {
  historyLoading = historyLoading || readHistory().finally(() => { historyLoading = null; });
  return historyLoading;
}

async function readHistory() {
  const answer = await api('GET', '/api/history');
  if (!answer.ok || !answer.data) return;
  state.history = sinceRestart(answer.data.points || []).slice(-HISTORY_LIMIT);
  const last = state.history[state.history.length - 1];
  state.clockOffset = last ? last.t - performance.now() / 1000 : null;
  scheduleRedraw();
}

/// A status event of a new round adds its point; a round number going back means the rounds
/// restarted (a preset, a restarted agent): the history is read again.
function appendRound(status) {
  const last = state.history[state.history.length - 1];
  if (last && status.round < last.round) {
    state.history = [];
    loadHistory();
    return;
  }
  if (status.objective == null || (last && status.round <= last.round)) return;
  let t = status.t;
  if (!Number.isFinite(t)) {
    if (state.clockOffset == null) state.clockOffset = -performance.now() / 1000;
    t = performance.now() / 1000 + state.clockOffset;
  }
  state.history.push({
    round: status.round,
    captures: status.captures,
    t,
    objective: status.objective,
    excess: status.excess,
  });
  if (state.history.length > HISTORY_LIMIT) state.history.splice(0, state.history.length - HISTORY_LIMIT);
}

// ---- the room page ------------------------------------------------------------------------

function stateClass(text) {
  return `state state-${String(text).replace(/\s+/g, '-')}`;
}

function projectorRow(id) {
  const thumbnail = element('img', { alt: `what ${id} shows`, className: 'missing' });
  thumbnail.addEventListener('load', () => thumbnail.classList.remove('missing'));
  thumbnail.addEventListener('error', () => thumbnail.classList.add('missing'));
  const identify = element('button', { type: 'button', className: 'identify', textContent: 'Identify' });
  identify.addEventListener('click', action(async () => {
    const answer = await api('POST', '/api/identify', { projector: id, seconds: 5 });
    if (answer.ok) flash(`${id} shows its identify pattern for 5 s`);
    else flash(`identify ${id}: ${errorText(answer)}`, true);
  }));
  return element('tr', { dataset: { projector: id } },
    element('td', { className: 'id', textContent: id }),
    element('td', { className: 'state' }),
    element('td', { className: 'nodes' }),
    element('td', { className: 'shown' }),
    element('td', { className: 'frame' }, thumbnail),
    element('td', {}, identify));
}

/// Keeps one row per item in `items` (by `key`), in their order; rows of items gone are removed.
function syncRows(body, items, key, attribute, make, update) {
  const rows = new Map([...body.rows].map((row) => [row.getAttribute(attribute), row]));
  const wanted = items.map(key);
  for (const [id, row] of rows) {
    if (!wanted.includes(id)) {
      row.remove();
      rows.delete(id);
    }
  }
  items.forEach((item, k) => {
    const id = wanted[k];
    let row = rows.get(id);
    if (!row) {
      row = make(id);
      rows.set(id, row);
    }
    if (body.rows[k] !== row) body.insertBefore(row, body.rows[k] || null);
    update(row, item);
  });
}

function renderRoom(status) {
  setText($('room-name'), status.room || '');
  setText($('round'), status.round ?? '–');
  setText($('captures'), status.captures ?? '–');
  setText($('objective'), formatNumber(status.objective));
  setText($('excess'), formatExcess(status.excess));
  setText($('averaged'), status.averaged == null ? '–' : `${status.averaged} capture${status.averaged === 1 ? '' : 's'}`);
  setText($('restarts'), status.restarts ?? '–');
  setText($('shading'), status.shading_passes ?? '–');
  const dark = status.dark_target;
  setText($('dark-target'), !dark ? '–' : dark.patches ? `weight ${dark.weight}, ${dark.patches} patch${dark.patches === 1 ? '' : 'es'}` : 'off');
  // The camera's latency as the rounds found it: captures refused in a row as late.
  setText($('late-frames'), status.late_frames ? `${status.late_frames} (set stale_frames)` : 'none');
  setText($('settled'), status.paused ? 'paused' : status.settled ? 'settled' : 'converging');
  const camera = status.camera || {};
  const badge = $('camera-state');
  setText(badge, camera.state || '');
  badge.className = `badge ${camera.state === 'working' ? 'good' : camera.error ? 'bad' : 'warn'}`;
  $('camera-error').hidden = !camera.error;
  setText($('camera-error'), camera.error || '');
  const projectors = status.projectors || [];
  $('no-projectors').hidden = projectors.length > 0;
  syncRows($('projectors').tBodies[0], projectors, (p) => p.id, 'data-projector', projectorRow, (row, p) => {
    const cell = row.querySelector('.state');
    setText(cell, p.state);
    cell.className = stateClass(p.state);
    setText(row.querySelector('.nodes'), p.nodes ?? '–');
    setText(row.querySelector('.shown'), p.shown ?? '–');
    const img = row.querySelector('.frame img');
    if (!img.getAttribute('src')) img.src = frameUrl(p.id);
  });
  renderWarnings(status.warnings || []);
}

function frameUrl(id) {
  return `/api/projectors/${encodeURIComponent(id)}/frame.png?t=${Date.now()}`;
}

function refreshThumbnails() {
  if (state.page !== 'room' || document.hidden) return;
  for (const row of $('projectors').tBodies[0].rows) {
    row.querySelector('.frame img').src = frameUrl(row.dataset.projector);
  }
}

let warningsKey = '';
function renderWarnings(warnings) {
  const recent = warnings.slice(-12).reverse();
  const key = JSON.stringify(recent);
  if (key === warningsKey) return;
  warningsKey = key;
  const list = $('warnings');
  list.replaceChildren(...recent.map((w) => {
    const when = new Date(w.unix_ms);
    return element('li', {},
      element('time', { dateTime: when.toISOString(), textContent: when.toLocaleTimeString() }),
      element('span', { className: `level-${w.level}`, textContent: w.level }),
      element('span', { textContent: w.message }));
  }));
  if (!recent.length) list.append(element('li', { className: 'empty', textContent: 'No warnings.' }));
}

// ---- the action bar -----------------------------------------------------------------------

/// `''` stands for no preset (the survey's may be null: the camera agent's config names it).
function fillPresets(select, presets, current) {
  const names = presets || [];
  if ([...select.options].map((o) => o.value).join('\n') !== names.join('\n')) {
    select.replaceChildren(...names.map((name) => element('option', { value: name, textContent: name || '(the config\'s)' })));
  }
  if (current != null && document.activeElement !== select && select.value !== current) select.value = current;
}

function renderActions(status) {
  const pause = $('pause');
  setText(pause, status.paused ? 'Resume' : 'Pause');
  $('paused-badge').hidden = !status.paused;
  fillPresets($('preset'), status.presets, status.preset);
}

function bindActions() {
  $('pause').addEventListener('click', action(async () => {
    const paused = state.status && state.status.paused;
    const answer = await api('POST', paused ? '/api/resume' : '/api/pause');
    if (!answer.ok) return flash(`${paused ? 'resume' : 'pause'}: ${errorText(answer)}`, true);
    const now = answer.data ? answer.data.paused : !paused;
    if (state.status) state.status.paused = now;
    renderActions(state.status || { paused: now });
    flash(now ? 'paused: the rounds stop, the projectors keep their light' : 'resumed');
  }));
  $('apply-preset').addEventListener('click', action(async () => {
    const preset = $('preset').value;
    const answer = await api('POST', '/api/preset', { preset });
    if (answer.ok) flash(`preset ${preset}: its light is measured, the rounds restart`);
    else flash(`preset ${preset}: ${errorText(answer)}`, true);
  }));
  $('calibrate-all').addEventListener('click', action(() => calibrate({})));
  $('snapshot').addEventListener('click', action(async () => {
    const answer = await api('POST', '/api/snapshot');
    if (answer.ok) flash(`snapshot written to ${answer.data && answer.data.path}`);
    else flash(`snapshot: ${errorText(answer)}`, true);
  }));
  $('logout').addEventListener('click', action(async () => {
    await fetch('/logout', { method: 'POST', headers: { 'X-Roomlight-CSRF': state.csrf }, credentials: 'same-origin' });
    location.assign('/login');
  }));
}

// ---- the survey page ----------------------------------------------------------------------

const SAMPLE_KEYS = ['saturation', 'read_noise', 'shot_noise', 'max_nonuniformity'];

function surveyMessage(text, kind = '') {
  const box = $('survey-message');
  box.textContent = text;
  box.className = kind;
}

/// Takes the survey `loaded` ({version, survey}) as the one edited, dropping any edits.
function useSurvey(loaded) {
  state.survey = loaded;
  state.draft = loaded ? structuredClone(loaded.survey) : null;
  state.dirty = false;
  setMode('none');
  renderSurvey();
}

let surveyLoading = null;
function loadSurvey() {
  surveyLoading = surveyLoading || readSurvey().finally(() => { surveyLoading = null; });
  return surveyLoading;
}

async function readSurvey() {
  const answer = await api('GET', '/api/survey');
  if (answer.status === 404) useSurvey(null);
  else if (answer.ok && answer.data) useSurvey(answer.data);
  else surveyMessage(`reading the survey: ${errorText(answer)}`, 'bad');
}

function edited() {
  state.dirty = true;
  renderSurvey();
}

function renderSurvey() {
  const draft = state.draft;
  $('survey-missing').hidden = !!state.survey;
  setText($('survey-state'), !draft ? '' : state.dirty ? 'unsaved edits' : `version ${String(state.survey.version).slice(0, 8)}`);
  const charts = draft ? draft.charts || [] : [];
  const chartList = $('chart-list');
  chartList.replaceChildren(...charts.map((chart, k) => element('li', {},
    element('span', { textContent: chart.name || '(no name)' }),
    deleteButton(`delete chart ${chart.name}`, () => charts.splice(k, 1)))));
  if (!charts.length) chartList.append(element('li', { className: 'empty', textContent: 'No chart.' }));
  const polygons = draft ? draft.target || [] : [];
  const polygonList = $('polygon-list');
  polygonList.replaceChildren(...polygons.map((polygon, k) => element('li', {},
    element('span', { textContent: `polygon ${k + 1}: ${polygon.length} points` }),
    deleteButton(`delete polygon ${k + 1}`, () => polygons.splice(k, 1)))));
  if (!polygons.length) {
    // A survey written by `roomlight calibrate --survey-only` has the target as pixels only:
    // kept as they are until a polygon is drawn.
    const pixels = draft && draft.target_pixels;
    const text = pixels ? `No polygon: the target is ${pixels} pixels from the file, kept unless you draw one.` : 'No target polygon.';
    polygonList.append(element('li', { className: 'empty', textContent: text }));
  }
  for (const key of SAMPLE_KEYS) {
    const input = $(`sample-${key}`);
    const value = draft && draft.sample ? draft.sample[key] : '';
    // Levels are single precision in the file: 0.98 comes back as 0.980000019073…
    const shown = typeof value === 'number' ? String(Number(value.toPrecision(6))) : value ?? '';
    if (document.activeElement !== input) input.value = shown;
  }
  fillSurveyPresets();
  setStageAspect();
  updateSurveyControls();
  scheduleRedraw();
}

function fillSurveyPresets() {
  const presets = (state.status && state.status.presets) || [];
  const current = state.draft ? state.draft.preset ?? '' : null;
  fillPresets($('survey-preset'), ['', ...presets], current);
}

function deleteButton(label, remove) {
  const button = element('button', { type: 'button', className: 'quiet', textContent: 'Delete', title: label });
  button.setAttribute('aria-label', label);
  button.addEventListener('click', () => {
    remove();
    edited();
  });
  return button;
}

const HINTS = {
  none: 'Pick a tool, then click on the image.',
  chart: ['Click the chart\'s top-left corner (patch 1).', 'Click its top-right corner.',
    'Click its bottom-right corner.', 'Click its bottom-left corner.'],
  naming: 'Name the chart as the room\'s config does, then add it.',
  target: 'Click the target\'s outline point by point, then close the polygon.',
};

function setMode(mode) {
  state.mode = mode;
  if (mode === 'none' || mode === 'chart' || mode === 'target') state.points = [];
  $('chart-pending').hidden = mode !== 'naming';
  if (mode === 'naming') {
    $('chart-name').value = '';
    $('chart-name').focus();
  }
  updateSurveyControls();
  scheduleRedraw();
}

function updateSurveyControls() {
  const editable = !!state.draft;
  const hint = HINTS[state.mode];
  setText($('mode-hint'), Array.isArray(hint) ? hint[Math.min(state.points.length, 3)] : hint);
  $('add-chart').classList.toggle('active', state.mode === 'chart' || state.mode === 'naming');
  $('draw-target').classList.toggle('active', state.mode === 'target');
  for (const id of ['add-chart', 'draw-target', 'save-survey', 'reload-survey']) $(id).disabled = !editable;
  $('close-polygon').disabled = !(state.mode === 'target' && state.points.length >= 3);
  $('undo-point').disabled = !((state.mode === 'target' || state.mode === 'chart') && state.points.length);
  $('cancel-mode').disabled = state.mode === 'none';
}

/// A click on the overlay, in full camera pixels (the image is shown scaled down).
function cameraPoint(event) {
  const canvas = event.currentTarget;
  const [cw, ch] = cameraSize();
  const clamp = (v, high) => Math.min(Math.max(Math.round(v * 10) / 10, 0), high);
  return [
    clamp((event.offsetX / canvas.clientWidth) * cw, cw),
    clamp((event.offsetY / canvas.clientHeight) * ch, ch),
  ];
}

function surveyClick(event) {
  if (!state.draft || (state.mode !== 'chart' && state.mode !== 'target')) return;
  state.points.push(cameraPoint(event));
  if (state.mode === 'chart' && state.points.length === 4) setMode('naming');
  updateSurveyControls();
  scheduleRedraw();
}

function confirmChart() {
  const name = $('chart-name').value.trim();
  if (!name) {
    surveyMessage('a chart needs a name', 'bad');
    $('chart-name').focus();
    return;
  }
  state.draft.charts = state.draft.charts || [];
  state.draft.charts.push({ name, corners: state.points.slice() });
  setMode('none');
  edited();
}

function closePolygon() {
  if (state.mode !== 'target' || state.points.length < 3) return;
  state.draft.target = state.draft.target || [];
  state.draft.target.push(state.points.slice());
  state.points = [];
  edited();
}

async function saveSurvey() {
  const draft = state.draft;
  const answer = await api('PUT', '/api/survey', { version: state.survey.version, survey: draft });
  if (answer.status === 200) {
    state.survey = { version: answer.data.version, survey: structuredClone(draft) };
    state.dirty = false;
    renderSurvey();
    // The camera agent reads its survey when it starts (docs/console.md).
    surveyMessage('saved — used when the camera agent starts again (systemctl restart roomlight-camera)', 'good');
  } else if (answer.status === 409 && answer.data && answer.data.survey) {
    useSurvey({ version: answer.data.version, survey: answer.data.survey });
    surveyMessage('changed meanwhile — reloaded', 'bad');
  } else {
    surveyMessage(errorText(answer), 'bad');
  }
}

async function capture() {
  surveyMessage('taking a photograph…');
  const answer = await api('POST', '/api/capture');
  if (!answer.ok) return surveyMessage(`capture: ${errorText(answer)}`, 'bad');
  loadImages(answer.data.seq);
  surveyMessage(`captured ${answer.data.width}×${answer.data.height}`);
}

function bindSurvey() {
  const overlay = $('survey-overlay');
  overlay.addEventListener('click', surveyClick);
  $('capture').addEventListener('click', action(capture));
  $('add-chart').addEventListener('click', () => setMode(state.mode === 'chart' ? 'none' : 'chart'));
  $('draw-target').addEventListener('click', () => setMode(state.mode === 'target' ? 'none' : 'target'));
  $('close-polygon').addEventListener('click', closePolygon);
  $('cancel-mode').addEventListener('click', () => setMode('none'));
  $('undo-point').addEventListener('click', () => {
    state.points.pop();
    updateSurveyControls();
    scheduleRedraw();
  });
  $('confirm-chart').addEventListener('click', confirmChart);
  $('chart-name').addEventListener('keydown', (event) => {
    if (event.key === 'Enter') confirmChart();
    if (event.key === 'Escape') setMode('none');
  });
  for (const key of SAMPLE_KEYS) {
    $(`sample-${key}`).addEventListener('input', (event) => {
      if (!state.draft) return;
      const text = event.currentTarget.value.trim();
      state.draft.sample = state.draft.sample || {};
      // Sent as typed: an empty or wrong field comes back as a 422 naming it.
      state.draft.sample[key] = text === '' ? null : Number(text);
      edited();
    });
  }
  $('survey-preset').addEventListener('change', (event) => {
    if (!state.draft) return;
    state.draft.preset = event.currentTarget.value || null;
    edited();
  });
  $('save-survey').addEventListener('click', action(saveSurvey));
  $('reload-survey').addEventListener('click', action(async () => {
    await loadSurvey();
    surveyMessage('edits discarded');
  }));
}

// ---- the calibration page -----------------------------------------------------------------

function calibrationRow(id) {
  // Asked for as soon as a result appears, a map may not be ready yet (the model is being
  // rebuilt): asked again twice, 2 s apart, while the result is the same.
  const image = (kind) => {
    const img = element('img', { alt: `${kind} of ${id}`, className: 'missing' });
    img.addEventListener('load', () => img.classList.remove('missing'));
    img.addEventListener('error', () => {
      img.classList.add('missing');
      const tries = Number(img.dataset.tries || 0);
      if (!img.dataset.url || tries >= 2) return;
      const url = img.dataset.url;
      img.dataset.tries = String(tries + 1);
      setTimeout(() => {
        if (img.dataset.url === url) img.src = `${url}&try=${tries + 1}`;
      }, 2000);
    });
    return img;
  };
  const button = element('button', { type: 'button', className: 'calibrate', textContent: 'Calibrate' });
  button.addEventListener('click', action(() => calibrate({ projector: id })));
  return element('tr', { dataset: { calibrate: id } },
    element('td', { className: 'id', textContent: id }),
    element('td', { className: 'state' }),
    element('td', { className: 'decoded' }),
    element('td', { className: 'nodes' }),
    element('td', { className: 'captures' }),
    element('td', { className: 'at-round' }),
    element('td', { className: 'warnings' }),
    element('td', { className: 'coverage' }, image('coverage')),
    element('td', { className: 'attenuation' }, image('attenuation')),
    element('td', {}, button));
}

async function calibrate(body) {
  const answer = await api('POST', '/api/calibrate', body);
  if (answer.ok) {
    const queued = (answer.data && answer.data.queued) || [];
    flash(queued.length ? `calibration queued: ${queued.join(', ')}` : 'nothing to calibrate');
  } else {
    flash(`calibrate ${body.projector || 'all'}: ${errorText(answer)}`, true);
  }
}

function renderCalibration(status) {
  const calibration = status.calibration || {};
  const running = calibration.running;
  const progress = $('calibration-progress');
  progress.hidden = !running;
  if (running) {
    progress.max = Math.max(1, running.expected || 0);
    progress.value = Math.min(running.done || 0, progress.max);
    setText($('calibration-text'), `${(running.projectors || []).join(', ')}: ${running.stage}, ${running.done} of ${running.expected}`);
  } else {
    setText($('calibration-text'), 'idle');
  }
  const results = new Map((calibration.results || []).map((r) => [r.projector, r]));
  const projectors = new Map((status.projectors || []).map((p) => [p.id, p]));
  const ids = [...new Set([...projectors.keys(), ...results.keys()])];
  syncRows($('calibration').tBodies[0], ids, (id) => id, 'data-calibrate', calibrationRow, (row, id) => {
    const result = results.get(id);
    const projector = projectors.get(id);
    const measuring = running && (running.projectors || []).includes(id);
    const shown = measuring ? 'calibrating' : projector ? projector.state : 'gone';
    const cell = row.querySelector('.state');
    setText(cell, shown);
    cell.className = stateClass(shown);
    // `decoded` is null when a hot calibration measured the attenuation only.
    const decoded = result && result.decoded != null ? `${(result.decoded * 100).toFixed(1)}%` : result ? 'attenuation only' : '–';
    setText(row.querySelector('.decoded'), decoded);
    setText(row.querySelector('.nodes'), result ? result.nodes : '–');
    setText(row.querySelector('.captures'), result ? result.captures : '–');
    setText(row.querySelector('.at-round'), result ? result.at_round : '–');
    const warnings = result ? result.warnings || [] : [];
    setText(row.querySelector('td.warnings'), warnings.length ? warnings.join('; ') : result ? 'none' : '–');
    const key = result ? JSON.stringify([result.at_round, result.captures, result.decoded, result.nodes]) : '';
    if (state.calibrationKeys.get(id) !== key) {
      state.calibrationKeys.set(id, key);
      for (const img of row.querySelectorAll('img')) {
        img.classList.add('missing');
        img.dataset.url = '';
      }
      if (!result) return;
      const version = encodeURIComponent(key);
      const base = `/api/calibration/${encodeURIComponent(id)}`;
      for (const kind of ['coverage', 'attenuation']) {
        const img = row.querySelector(`.${kind} img`);
        img.dataset.url = `${base}/${kind}.png?v=${version}`;
        img.dataset.tries = '0';
        img.src = img.dataset.url;
      }
    }
  });
}

// ---- status: read once, then followed over Server-Sent Events -----------------------------

function onStatus(status) {
  state.status = status;
  appendRound(status);
  if (status.image && status.image.seq !== state.imageSeq) loadImages(status.image.seq);
  // Another console (or a hand) changed the survey: shown unless edits here would be lost.
  const version = status.survey && status.survey.version;
  if (version && !state.dirty && state.mode === 'none' && (!state.survey || state.survey.version !== version)) {
    loadSurvey();
  }
  renderActions(status);
  renderRoom(status);
  renderCalibration(status);
  fillSurveyPresets();
  setStageAspect();
  scheduleRedraw();
}

function connectEvents() {
  const source = new EventSource('/api/events');
  source.addEventListener('status', (event) => {
    $('disconnected').hidden = true;
    onStatus(JSON.parse(event.data));
  });
  source.addEventListener('open', () => { $('disconnected').hidden = true; });
  source.addEventListener('error', () => {
    $('disconnected').hidden = false;
    // The browser retries by itself unless the answer was not an event stream (a 401 after
    // the session ended, a proxy's error page): then the session is checked and we retry.
    if (source.readyState === EventSource.CLOSED) {
      setTimeout(async () => {
        try {
          await api('GET', '/api/session');
        } catch {
          // Offline: try the stream again anyway.
        }
        connectEvents();
      }, 2000);
    }
  });
}

async function start() {
  window.addEventListener('hashchange', route);
  route();
  for (const id of ['camera-image', 'survey-image']) watchImage($(id));
  bindActions();
  bindSurvey();
  updateSurveyControls();
  try {
    const session = await api('GET', '/api/session');
    state.csrf = (session.data && session.data.csrf) || '';
    const [, , status] = await Promise.all([loadHistory(), loadSurvey(), api('GET', '/api/status')]);
    if (status.ok && status.data) onStatus(status.data);
  } catch (error) {
    if (error.message !== 'not logged in') flash(`the camera agent does not answer: ${error.message}`, true);
  }
  connectEvents();
  setInterval(refreshThumbnails, THUMBNAIL_MS);
  new ResizeObserver(scheduleRedraw).observe(document.querySelector('main'));
}

start();
