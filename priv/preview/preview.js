'use strict';
// RingTracer live preview: draws one job from its Server-Sent Events stream
// (frames: job, atom, release, frame, ev, move, final, end; see
// RingTracer.Preview.Log). A sequence (several images) shows its oldest image
// in flight (the highest complete when none is), the images in flight, a
// strip of the highest images complete with their times, and keeps its lanes to
// the latest MAX_BARS atoms and MAX_MARKS events.
(function () {
  const $ = (id) => document.getElementById(id);
  const img = $('image'), overlay = $('overlay'), lanes = $('lanecanvas');
  const ictx = img.getContext('2d'), octx = overlay.getContext('2d'), lctx = lanes.getContext('2d');
  let job = null, pixels = null, k = 1, laneH = 18, dirty = false, ended = false;
  const MAX_BARS = 4096, MAX_MARKS = 4096;
  // A sequence's: atoms an image, images in flight by index, the latest
  // complete, the one shown, images complete so far and their mean time.
  const q = { on: false, m: 1, flight: new Map(), last: null, shown: null, completed: 0, mean: 0, at: 0 };
  const s = {
    done: 0, rays: 0, now: 0, tracer: [], seen: {}, bars: [], marks: [], prevEnd: [], fed: [],
    traced: [], given: [], received: [], own: [],
    msgs: { result: 0, offer: 0, pass: 0, give: 0, back: 0, handover: 0, steal: 0, refuse: 0, returned: 0 },
    final: null
  };

  function status(text) { $('status').textContent = text; }
  function fmt(n) { return n >= 1e6 ? (n / 1e6).toFixed(2) + ' M' : n >= 1e3 ? (n / 1e3).toFixed(1) + ' k' : String(Math.round(n)); }
  function ms(us) { return us >= 1e6 ? (us / 1e6).toFixed(2) + ' s' : (us / 1e3).toFixed(1) + ' ms'; }
  function cell(tr, text, cls) { const td = document.createElement('td'); td.textContent = text; if (cls) td.className = cls; tr.appendChild(td); return td; }

  function onJob(d) {
    job = d;
    q.m = d.m || d.owners.length;
    const w = d.width, h = d.height, n = d.children;
    img.width = w; img.height = h;
    pixels = ictx.createImageData(w, h);
    const scale = w >= 640 ? 640 / w : Math.max(1, Math.floor(640 / w));
    k = Math.max(1, Math.min(8, Math.ceil(scale)));
    overlay.width = w * k; overlay.height = h * k;
    for (const c of [img, overlay]) { c.style.width = (w * scale) + 'px'; c.style.height = (h * scale) + 'px'; }
    for (let i = 0; i < n; i++) { s.traced[i] = 0; s.given[i] = 0; s.received[i] = 0; s.own[i] = 0; s.prevEnd[i] = 0; s.fed[i] = 0; }
    for (const o of d.owners) s.own[o]++;
    laneH = Math.max(2, Math.min(22, 480 / n));
    const labels = $('labels');
    labels.textContent = '';
    for (let i = 0; i < n; i++) {
      const div = document.createElement('div');
      div.className = 'lane-label';
      div.dataset.child = i;
      div.style.height = laneH + 'px';
      div.style.lineHeight = laneH + 'px';
      div.style.borderLeftColor = d.palette[i];
      div.style.fontSize = laneH >= 10 ? '11px' : '0';
      div.textContent = 'child ' + i + ' · ' + d.nodes[i] + (d.speeds[i] !== 1 ? ' · ×' + d.speeds[i] : '');
      div.title = div.textContent;
      labels.appendChild(div);
    }
    $('strategy').textContent = d.strategy.replace('RingTracer.Strategy.', '') + ', ' + n + ' children, ' + d.total + ' atoms, ' + w + '×' + h;
    buildChildren();
    if (d.frames > 1) sequence();
    document.body.dataset.state = 'running';
    status('rendering');
    dirty = true;
  }

  function buildChildren() {
    const tb = $('children').tBodies[0];
    tb.textContent = '';
    const n = job.children;
    if (n > 64) { const tr = tb.insertRow(); cell(tr, n + ' children: see the lanes', 'name').colSpan = 8; return; }
    for (let i = 0; i < n; i++) {
      const tr = tb.insertRow();
      const sw = document.createElement('span'); sw.className = 'swatch'; sw.style.background = job.palette[i];
      cell(tr, '').appendChild(sw);
      cell(tr, String(i)); cell(tr, job.nodes[i], 'name'); cell(tr, String(job.speeds[i]));
      for (let j = 0; j < 4; j++) cell(tr, '0');
    }
  }

  // Atom a is atom a mod m of its image.
  function span(a) {
    const [first, count] = job.spans[a % q.m], w = job.width;
    const last = first + count - 1;
    return { x0: first % w, y0: Math.floor(first / w), x1: last % w, y1: Math.floor(last / w), first: first, count: count };
  }

  // A piece of an atom (adaptive atoms) covers parts p[0] to p[1] of p[2].
  function pieceSpan(d) {
    const sp = span(d.a);
    if (!d.p) return sp;
    const [lo, hi, n] = d.p, first = sp.first + Math.floor(lo * sp.count / n);
    const count = Math.floor(hi * sp.count / n) - Math.floor(lo * sp.count / n), w = job.width, last = first + count - 1;
    return { x0: first % w, y0: Math.floor(first / w), x1: last % w, y1: Math.floor(last / w), first: first, count: count };
  }

  function onAtom(d) {
    const key = d.p ? d.a + ':' + d.p.join(':') : String(d.a);
    if (!job) return;
    // A sequence's atom goes to its image's own pixels, and to the canvas
    // when that image is the one shown.
    const rec = q.on ? image(Math.floor(d.a / q.m)) : null;
    const seen = rec ? rec.seen : s.seen, tracer = rec ? rec.tracer : s.tracer, px = rec ? rec.pixels : pixels;
    if (seen[key]) return;
    seen[key] = true;
    tracer[d.a % q.m] = d.c;
    const raw = atob(d.px), p = px.data, sp = pieceSpan(d);
    for (let i = 0; i < sp.count; i++) {
      const o = (sp.first + i) * 4, j = i * 3;
      p[o] = raw.charCodeAt(j); p[o + 1] = raw.charCodeAt(j + 1); p[o + 2] = raw.charCodeAt(j + 2); p[o + 3] = 255;
    }
    const part = d.p ? (d.p[1] - d.p[0]) / d.p[2] : 1;
    if (rec) {
      rec.done += part;
      if (q.shown === rec) {
        ictx.putImageData(px, 0, 0, 0, sp.y0, job.width, sp.y1 - sp.y0 + 1);
        if ($('outlines').checked) outline(d.a, d.c);
      } else show();
    } else {
      ictx.putImageData(pixels, 0, 0, 0, sp.y0, job.width, sp.y1 - sp.y0 + 1);
      if ($('outlines').checked) outline(d.a, d.c);
    }
    s.done += part; s.rays += d.rays; s.traced[d.c]++; s.msgs.result++;
    if (d.at !== null) {
      s.now = Math.max(s.now, d.at);
      // Live, an atom's bar runs from the child's previous atom (its
      // grandchild never waits while it holds atoms) or from the atoms
      // last handed to it; the final frame has the exact times.
      const start = Math.max(s.prevEnd[d.c], s.fed[d.c]);
      s.bars.push({ c: d.c, a: d.a, start: start, end: d.at });
      if (q.on && s.bars.length > MAX_BARS) s.bars.splice(0, s.bars.length - MAX_BARS);
      s.prevEnd[d.c] = d.at;
    }
    dirty = true;
  }

  function onEvent(d) {
    if (!job) return;
    s.msgs[d.kind] = (s.msgs[d.kind] || 0) + 1;
    s.marks.push(d);
    if (q.on && s.marks.length > MAX_MARKS) s.marks.splice(0, s.marks.length - MAX_MARKS);
    s.now = Math.max(s.now, d.at);
    dirty = true;
  }

  function onMove(d) {
    if (!job) return;
    if (d.from !== 'parent') s.given[d.from] += d.n;
    s.received[d.to] += d.n;
    s.fed[d.to] = d.at;
    s.msgs.handover++;
    s.now = Math.max(s.now, d.at);
    dirty = true;
  }

  function path(ctx, sp, w, f) {
    ctx.beginPath();
    if (sp.y0 === sp.y1) { ctx.rect(sp.x0 * f, sp.y0 * f, (sp.x1 - sp.x0 + 1) * f, f); return; }
    const pts = [[sp.x0, sp.y0], [w, sp.y0], [w, sp.y1], [sp.x1 + 1, sp.y1], [sp.x1 + 1, sp.y1 + 1], [0, sp.y1 + 1], [0, sp.y0 + 1], [sp.x0, sp.y0 + 1]];
    ctx.moveTo(pts[0][0] * f, pts[0][1] * f);
    for (const [x, y] of pts.slice(1)) ctx.lineTo(x * f, y * f);
    ctx.closePath();
  }

  function outline(a, c) {
    const sp = span(a);
    path(octx, sp, job.width, k);
    octx.globalAlpha = 0.35; octx.fillStyle = job.palette[job.owners[a % q.m]]; octx.fill();
    octx.globalAlpha = 1; octx.lineWidth = Math.max(1, k / 2); octx.strokeStyle = job.palette[c];
    octx.save(); octx.clip(); octx.lineWidth *= 2; octx.stroke(); octx.restore();
  }

  function outlines() {
    octx.clearRect(0, 0, overlay.width, overlay.height);
    const tracer = q.on ? (q.shown ? q.shown.tracer : []) : s.tracer;
    if ($('outlines').checked && job) for (let a = 0; a < tracer.length; a++) if (tracer[a] !== undefined) outline(a, tracer[a]);
  }
  $('outlines').addEventListener('change', outlines);

  // A sequence: the page shows its images.
  function sequence() {
    if (q.on) return;
    q.on = true;
    $('sequence').hidden = false;
    // A sequence of one image, seen as a single image until now (the page
    // opened on it running): what is drawn is its image's.
    if (s.done > 0) {
      const rec = image(0);
      Object.assign(rec, { pixels: pixels, done: s.done, tracer: s.tracer, seen: s.seen });
      s.tracer = []; s.seen = {};
    }
  }

  function image(f) {
    let rec = q.flight.get(f);
    if (!rec) {
      rec = { f: f, n: null, done: 0, seen: {}, tracer: [], pixels: ictx.createImageData(job.width, job.height), thumb: null };
      q.flight.set(f, rec);
      dirty = true;
    }
    return rec;
  }

  // The image shown: the oldest in flight, else the latest complete.
  function show() {
    let rec = null;
    for (const r of q.flight.values()) if (!rec || r.f < rec.f) rec = r;
    rec = rec || q.last;
    if (rec === q.shown) return;
    q.shown = rec;
    ictx.clearRect(0, 0, img.width, img.height);
    if (rec && rec.thumb && rec.done < q.m) {
      // Complete, but the page missed atoms of it (it lagged, or joined
      // late): its thumbnail, scaled up.
      ictx.imageSmoothingEnabled = false;
      ictx.drawImage(rec.thumb, 0, 0, img.width, img.height);
    } else if (rec) ictx.putImageData(rec.pixels, 0, 0);
    outlines();
    dirty = true;
  }

  function onRelease(d) {
    if (!job) return;
    sequence();
    if (d.f !== null) image(d.f).n = d.n;
    show();
  }

  function onImage(d) {
    if (!job) return;
    sequence();
    let rec = d.f !== null ? q.flight.get(d.f) : null;
    if (rec) q.flight.delete(d.f);
    else rec = { f: d.f, done: 0, seen: {}, tracer: [], pixels: null };
    rec.n = d.n;
    // Images no longer in flight whose own frame this page missed (it
    // lagged, and the log forgot them): complete too.
    const flight = new Set(d.flight);
    for (const f of [...q.flight.keys()]) if (!flight.has(f)) q.flight.delete(f);
    q.completed = d.completed; q.mean = d.mean_us; q.at = Math.max(q.at, d.at);
    s.now = Math.max(s.now, d.at);
    const box = document.createElement('div'), c = document.createElement('canvas'), cap = document.createElement('span');
    box.className = 'thumb'; box.dataset.n = d.n; box.dataset.us = d.us;
    c.width = d.tw; c.height = d.th;
    const z = Math.max(1, Math.floor(96 / Math.max(d.tw, d.th)));
    c.style.width = (d.tw * z) + 'px'; c.style.height = (d.th * z) + 'px';
    if (d.px) {
      const t = c.getContext('2d'), data = t.createImageData(d.tw, d.th), raw = atob(d.px);
      for (let i = 0; i < d.tw * d.th; i++) {
        data.data[i * 4] = raw.charCodeAt(i * 3); data.data[i * 4 + 1] = raw.charCodeAt(i * 3 + 1); data.data[i * 4 + 2] = raw.charCodeAt(i * 3 + 2); data.data[i * 4 + 3] = 255;
      }
      t.putImageData(data, 0, 0);
      rec.thumb = c;
    }
    cap.textContent = d.n + ' · ' + ms(d.us);
    box.appendChild(c); box.appendChild(cap);
    // The strip: the highest numbers complete, in order (as the log keeps them).
    const strip = $('strip');
    const after = [...strip.children].find((e) => +e.dataset.n > d.n);
    strip.insertBefore(box, after || null);
    while (strip.children.length > job.strip) strip.removeChild(strip.firstChild);
    if ((rec.pixels || rec.thumb) && (!q.last || d.n > q.last.n)) q.last = rec;
    q.shown = null;
    show();
    dirty = true;
  }

  function drawSequence() {
    let inflight = 0;
    const ids = [...q.flight.keys()].sort((a, b) => a - b), box = $('inflight');
    box.textContent = '';
    for (const f of ids) {
      const r = q.flight.get(f);
      inflight += r.done;
      if (box.children.length < 16) {
        const chip = document.createElement('span');
        chip.className = 'chip' + (r === q.shown ? ' main' : '');
        chip.textContent = (r.n === null ? '?' : r.n) + ' (' + Math.round(r.done) + '/' + q.m + ')';
        box.appendChild(chip);
      }
    }
    if (ids.length > 16) box.appendChild(document.createTextNode('… ' + ids.length + ' in all'));
    if (ids.length === 0) box.textContent = '–';
    s.done = q.completed * q.m + inflight;
    $('framesdone').textContent = q.completed + ' / ' + job.frames + ' complete';
    $('frametime').textContent = q.completed > 0
      ? 'mean ' + ms(q.mean) + ' from release to last pixel; one complete every ' + ms(q.at / q.completed)
      : '–';
    const r = q.shown;
    $('showing').textContent = !r ? '' : (q.flight.has(r.f) ? 'frame ' + (r.n === null ? '?' : r.n) + ', the oldest in flight: ' + Math.round(r.done) + ' / ' + q.m + ' atoms' : 'frame ' + r.n + ', the latest complete');
  }

  function drawLanes() {
    const n = job.children, W = Math.max(200, $('lanes').clientWidth - 222), H = Math.ceil(n * laneH);
    if (lanes.width !== W || lanes.height !== H) { lanes.width = W; lanes.height = H; lanes.style.width = W + 'px'; lanes.style.height = H + 'px'; }
    lctx.clearRect(0, 0, W, H);
    const bars = s.final ? s.final.atoms.map((r) => ({ c: r.child, a: r.atom, start: r.start_us, end: r.end_us })) : s.bars;
    const marks = s.final ? s.final.events.map((e) => ({ kind: e.kind, from: e.from, to: e.to, at: e.at_us })) : s.marks;
    let tmax = Math.max(1, s.now, s.final ? s.final.elapsed_us : 0);
    for (const b of bars) tmax = Math.max(tmax, b.end);
    // A sequence's lanes start at the first atom kept.
    let t0 = 0;
    if (q.on && bars.length) t0 = bars.reduce((t, b) => Math.min(t, b.start), Infinity);
    const x = (t) => ((t - t0) / Math.max(1, tmax - t0)) * (W - 4) + 2;
    for (let i = 0; i < n; i++) { if (i % 2) { lctx.fillStyle = '#f6f6f6'; lctx.fillRect(0, i * laneH, W, laneH); } }
    for (const b of bars) {
      const owner = job.owners[b.a % q.m], y = b.c * laneH + (laneH > 4 ? 1 : 0), h = laneH > 4 ? laneH - 2 : laneH;
      const x0 = x(b.start), bw = Math.max(1, x(b.end) - x0);
      lctx.fillStyle = job.palette[owner]; lctx.fillRect(x0, y, bw, h);
      if (owner !== b.c && laneH > 4) { lctx.strokeStyle = '#222'; lctx.lineWidth = 1; lctx.strokeRect(x0 + 0.5, y + 0.5, bw - 1, h - 1); }
    }
    for (const m of marks) {
      if (m.at < t0) continue;
      const xm = x(m.at), y0 = m.from * laneH + laneH / 2;
      const colour = { offer: '#777', pass: '#999', give: '#c22', steal: '#26c' }[m.kind];
      if (colour && typeof m.to === 'number' && m.to < n) {
        const y1 = m.to * laneH + laneH / 2;
        lctx.strokeStyle = colour; lctx.lineWidth = 1.2; lctx.setLineDash(m.kind === 'pass' ? [3, 2] : []);
        lctx.beginPath(); lctx.moveTo(xm, y0); lctx.lineTo(xm, y1); lctx.stroke();
        lctx.setLineDash([]);
        const dir = y1 >= y0 ? 1 : -1;
        lctx.fillStyle = colour; lctx.beginPath(); lctx.moveTo(xm, y1); lctx.lineTo(xm - 3, y1 - 5 * dir); lctx.lineTo(xm + 3, y1 - 5 * dir); lctx.fill();
      } else {
        lctx.fillStyle = '#444'; lctx.fillRect(xm - 1, m.from * laneH, 2, laneH);
      }
    }
    $('axis').textContent = '';
    for (let i = 0; i <= 4; i++) { const sp = document.createElement('span'); sp.textContent = ms(t0 + ((tmax - t0) * i) / 4); $('axis').appendChild(sp); }
  }

  function drawCounters() {
    if (q.on) drawSequence();
    const t = s.final ? s.final.elapsed_us : s.now;
    $('atoms').textContent = Math.round(s.done * 100) / 100 + ' / ' + job.total;
    $('rate').textContent = t > 0 ? fmt(s.rays / (t / 1e6)) : '–';
    $('elapsed').textContent = ms(t);
    $('eta').textContent = s.final ? 'done' : s.done > 0 ? ms(((job.total - s.done) * t) / s.done) : '–';
    const tb = $('messages').tBodies[0];
    tb.textContent = '';
    const rows = s.final
      ? Object.entries(s.final.traffic).map(([kind, v]) => [kind, v.n, v.bytes])
      : [['results', s.msgs.result], ['help offers', s.msgs.offer], ['offers passed on', s.msgs.pass], ['hand-overs', s.msgs.handover], ['offers back', s.msgs.back + s.msgs.returned], ['steal requests', s.msgs.steal]].filter((r) => r[1] > 0);
    for (const r of rows) { const tr = tb.insertRow(); cell(tr, r[0], 'name'); cell(tr, String(r[1])); cell(tr, r[2] === undefined ? '' : fmt(r[2])); }
    const ctb = $('children').tBodies[0];
    if (job.children > 64) return;
    for (let i = 0; i < job.children; i++) {
      const c = s.final ? s.final.children[i] : null;
      const vals = c ? [c.own, c.given, c.received, c.traced] : [s.own[i], s.given[i], s.received[i], s.traced[i]];
      const tds = ctb.rows[i].cells;
      for (let j = 0; j < 4; j++) tds[4 + j].textContent = String(vals[j]);
    }
  }

  function frame() {
    if (dirty && job) { dirty = false; drawLanes(); drawCounters(); }
    requestAnimationFrame(frame);
  }

  function onFinal(d) {
    s.final = d.ok ? d : null;
    const t = $('finaltable');
    t.textContent = '';
    const row = (k, v) => { const tr = t.insertRow(); const th = document.createElement('th'); th.textContent = k; tr.appendChild(th); cell(tr, v); };
    if (!d.ok) { row('error', d.error); $('final').hidden = false; return; }
    const traffic = Object.values(d.traffic);
    const rays = d.children.reduce((a, c) => a + Object.entries(c.rays).filter(([k]) => k !== 'work').reduce((x, [, v]) => x + v, 0), 0);
    row('makespan', ms(d.elapsed_us));
    if (d.frames !== undefined) row('frames', d.frames + ', mean ' + ms(d.mean_us) + ' each from release to last pixel');
    row('stopping the children', ms(d.teardown_us));
    row('rays', fmt(rays) + ' (' + fmt(rays / (d.elapsed_us / 1e6)) + '/s)');
    row('messages', traffic.reduce((a, v) => a + v.n, 0) + ' (' + fmt(traffic.reduce((a, v) => a + v.bytes, 0)) + ' bytes)');
    row('atoms traced twice', String(d.duplicates));
    row('atoms redone after a failure', String(d.redone));
    const offers = d.children.reduce((a, c) => a + c.offers_sent, 0), hand = d.children.reduce((a, c) => a + c.handovers, 0);
    row('help offers sent', String(offers));
    row('hand-overs received', String(hand));
    const busy = d.children.map((c) => c.busy_us);
    row('busiest / idlest child', ms(Math.max(...busy)) + ' / ' + ms(Math.min(...busy)));
    $('final').hidden = false;
    dirty = true;
  }

  function onEnd() {
    ended = true;
    es.close();
    drawLanes(); drawCounters();
    if (job && q.on && s.final && q.completed === job.frames) {
      $('result').textContent = img.toDataURL('image/png');
      document.body.dataset.state = 'done';
      status('done: ' + q.completed + ' frames, ' + job.total + ' atoms');
    } else if (job && Math.abs(s.done - job.total) < 1e-6) {
      $('result').textContent = img.toDataURL('image/png');
      document.body.dataset.state = 'done';
      status('done: ' + s.done + ' atoms');
    } else {
      document.body.dataset.state = 'failed';
      status('the job ended without its image');
    }
  }

  const es = new EventSource('events');
  // The body carries the number of the last frame read (for tests).
  const on = (name, f) => es.addEventListener(name, (e) => { f(JSON.parse(e.data)); document.body.dataset.seq = e.lastEventId; });
  on('job', onJob); on('atom', onAtom); on('release', onRelease); on('frame', onImage); on('ev', onEvent); on('move', onMove); on('final', onFinal); on('end', onEnd);
  es.onerror = () => { if (!ended) status('connection lost; retrying…'); };
  requestAnimationFrame(frame);
})();
