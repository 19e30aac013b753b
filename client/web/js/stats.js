// Live numbers of the stream: per-stage GPU times (a table and a stacked chart of the last
// seconds) and fps, input→frame latency and bandwidth (counters and sparklines).

import { FLAG_KEYFRAME } from './frame.js';

const WINDOW_MS = 10000;
// Long enough to show a rate for slow streams (a software adapter renders BRSM at < 1 fps).
const RATE_WINDOW_MS = 5000;
const SAMPLE_EVERY_MS = 250;
const PALETTE = ['#4e79a7', '#f28e2b', '#e15759', '#76b7b2', '#59a14f', '#edc948', '#b07aa1',
  '#ff9da7', '#9c755f', '#bab0ac', '#86bcb6', '#d37295', '#fabfd2', '#8cd17d'];

function percentile(values, p) {
  if (values.length === 0) return null;
  const sorted = [...values].sort((a, b) => a - b);
  return sorted[Math.min(sorted.length - 1, Math.floor(p * sorted.length))];
}

const fmt = (v, digits = 1) => (v === null || v === undefined ? '–' : v.toFixed(digits));

export class Stats {
  constructor(elements) {
    this.el = elements;
    this.stageNames = [];
    this.frames = [];
    this.samples = [];
    this.total = 0;
    this.dropped = 0;
    this.lastSeq = 0;
    this.firstFrameAt = null;
    setInterval(() => this.sample(), SAMPLE_EVERY_MS);
  }

  setStageNames(names) {
    this.stageNames = names;
  }

  stageName(index) {
    return this.stageNames[index] || `stage ${index}`;
  }

  /**
   * The session's encoding and fps cap, for the target bitrate the frame line shows; with
   * `bitrate_kbps` null the server picks `autoBitsPerPixel` (from `/v1/server`) bits per pixel
   * of each frame at the fps cap, as `Encoding::bitrate_kbps_for` does.
   */
  setEncoding(encoding, fpsCap) {
    this.encoding = encoding;
    this.fpsCap = fpsCap;
  }

  setAutoBitsPerPixel(bits) {
    this.autoBitsPerPixel = bits;
  }

  /** The H.264 target of a frame of `width`×`height`, in kbit/s, and whether it is automatic. */
  targetKbps(width, height) {
    if (!this.encoding) return null;
    if (this.encoding.bitrate_kbps !== null && this.encoding.bitrate_kbps !== undefined) {
      return { kbps: this.encoding.bitrate_kbps, auto: false };
    }
    if (!this.autoBitsPerPixel || !this.fpsCap) return null;
    const kbps = Math.min(200000, Math.max(100, Math.round((this.autoBitsPerPixel * width * height * this.fpsCap) / 1000)));
    return { kbps, auto: true };
  }

  /**
   * Records a painted frame: `latencyMs` from the input it answers (null if none of ours),
   * `decodeMs` the time this page took to decode it.
   */
  frame(header, latencyMs, decodeMs) {
    const now = performance.now();
    if (this.lastSeq && header.seq > this.lastSeq + 1) this.dropped += header.seq - this.lastSeq - 1;
    this.lastSeq = Math.max(this.lastSeq, header.seq);
    this.total += 1;
    if (this.firstFrameAt === null) this.firstFrameAt = now;
    this.frames.push({ t: now, header, latencyMs, decodeMs });
    while (this.frames.length && this.frames[0].t < now - WINDOW_MS) this.frames.shift();
    this.el.frameCount.textContent = String(this.total);
    this.el.frameCount.dataset.count = String(this.total);
  }

  /** A new session numbers its frames from 1 again. */
  resetSequence() {
    this.lastSeq = 0;
  }

  recent(ms) {
    const since = performance.now() - ms;
    return this.frames.filter((f) => f.t >= since);
  }

  sample() {
    const now = performance.now();
    const recent = this.recent(RATE_WINDOW_MS);
    const latencies = recent.map((f) => f.latencyMs).filter((v) => v !== null);
    // Over the window, or since the first frame while the stream is younger than that.
    const seconds = this.firstFrameAt === null ? 1 : Math.max(0.25, Math.min(RATE_WINDOW_MS, now - this.firstFrameAt) / 1000);
    const sample = {
      t: now,
      fps: recent.length / seconds,
      mbps: (recent.reduce((sum, f) => sum + f.header.bytes, 0) * 8) / 1e6 / seconds,
      latency: percentile(latencies, 0.5),
    };
    this.samples.push(sample);
    while (this.samples.length && this.samples[0].t < sample.t - WINDOW_MS) this.samples.shift();
    this.render(sample, recent, latencies);
  }

  render(sample, recent, latencies) {
    const last = this.frames[this.frames.length - 1];
    const mean = (f) => (recent.length ? recent.reduce((s, r) => s + f(r), 0) / recent.length : null);
    this.el.fps.textContent = fmt(sample.fps);
    this.el.latency.textContent = latencies.length ? `${fmt(percentile(latencies, 0.5), 0)} / ${fmt(percentile(latencies, 0.95), 0)}` : '–';
    this.el.bandwidth.textContent = fmt(sample.mbps, 2);
    this.el.dropped.textContent = String(this.dropped);
    this.el.gpu.textContent = fmt(mean((f) => f.header.gpuMs), 2);
    this.el.encode.textContent = fmt(mean((f) => f.header.encodeMs), 2);
    this.el.readback.textContent = fmt(mean((f) => f.header.readbackMs), 2);
    this.el.decode.textContent = fmt(mean((f) => f.decodeMs), 2);
    if (last) {
      const h = last.header;
      const progress = h.samples > 0 ? ` · ${h.samples} spp, ±${(h.relativeError * 100).toFixed(1)} %` : '';
      // Video P-frames are often under a KiB: one decimal below 10 KiB.
      this.el.frameInfo.textContent = `#${h.seq} · ${h.width}×${h.height} · ${this.codecLabel(h)} · ${(h.bytes / 1024).toFixed(h.bytes < 10240 ? 1 : 0)} KiB${progress}`;
    }
    this.renderStageTable(recent);
    this.drawStages();
    sparkline(this.el.fpsChart, this.samples.map((s) => s.fps), '#59a14f');
    sparkline(this.el.latencyChart, this.samples.map((s) => s.latency), '#e15759');
    sparkline(this.el.bandwidthChart, this.samples.map((s) => s.mbps), '#4e79a7');
  }

  codecLabel(h) {
    if (h.codec === 'png') return 'PNG';
    if (h.codec === 'jpeg') return `JPEG q${h.quality}`;
    const t = this.targetKbps(h.width, h.height);
    const target = t ? ` · target ${(t.kbps / 1000).toFixed(1)} Mbit/s${t.auto ? ' (auto)' : ''}` : '';
    return `H.264${(h.flags & FLAG_KEYFRAME) !== 0 ? ' keyframe' : ''}${target}`;
  }

  renderStageTable(recent) {
    const sums = new Map();
    for (const f of recent) {
      for (const s of f.header.stages) sums.set(s.index, (sums.get(s.index) || 0) + s.ms);
    }
    const last = this.frames[this.frames.length - 1];
    const rows = [];
    for (const s of last ? last.header.stages : []) {
      const tr = document.createElement('tr');
      tr.dataset.stage = this.stageName(s.index);
      const swatch = document.createElement('td');
      swatch.className = 'swatch';
      swatch.style.background = PALETTE[s.index % PALETTE.length];
      const name = document.createElement('td');
      name.textContent = this.stageName(s.index);
      const now = document.createElement('td');
      now.textContent = s.reused ? 'reused' : s.ms.toFixed(3);
      if (s.reused) now.title = 'the output of an earlier frame with the same lights and poses';
      if (s.sharedBy > 1) {
        now.textContent += ` ÷ ${s.sharedBy}`;
        now.title = `made once for ${s.sharedBy} sessions' frames`
          + (s.reused ? ' by another session\'s frame' : ': this frame paid for it all, each frame\'s share is this over ' + s.sharedBy);
      }
      tr.dataset.reused = String(s.reused);
      const avg = document.createElement('td');
      avg.textContent = recent.length ? ((sums.get(s.index) || 0) / recent.length).toFixed(3) : '–';
      tr.append(swatch, name, now, avg);
      rows.push(tr);
    }
    this.el.stageRows.replaceChildren(...rows);
  }

  /** Stacked bars of per-stage GPU ms, one per frame, over the last WINDOW_MS. */
  drawStages() {
    const canvas = this.el.stageChart;
    const ctx = fitCanvas(canvas);
    const { width, height } = canvas;
    ctx.clearRect(0, 0, width, height);
    if (this.frames.length === 0) return;
    const totals = this.frames.map((f) => f.header.stages.reduce((s, st) => s + st.ms, 0));
    const max = niceMax(Math.max(...totals));
    const now = performance.now();
    const barWidth = Math.max(1, width / Math.max(60, this.frames.length));
    for (const f of this.frames) {
      const x = width - ((now - f.t) / WINDOW_MS) * width;
      let y = height;
      for (const s of f.header.stages) {
        const h = (s.ms / max) * height;
        ctx.fillStyle = PALETTE[s.index % PALETTE.length];
        ctx.fillRect(x, y - h, barWidth, h);
        y -= h;
      }
    }
    ctx.fillStyle = '#aaa';
    ctx.font = `${11 * devicePixelRatio}px system-ui, sans-serif`;
    ctx.fillText(`${max} ms`, 4, 12 * devicePixelRatio);
  }
}

function fitCanvas(canvas) {
  const w = Math.round(canvas.clientWidth * devicePixelRatio);
  const h = Math.round(canvas.clientHeight * devicePixelRatio);
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
  return canvas.getContext('2d');
}

function niceMax(v) {
  if (!(v > 0)) return 1;
  const p = 10 ** Math.floor(Math.log10(v));
  return [1, 2, 5, 10].map((m) => m * p).find((c) => c >= v);
}

function sparkline(canvas, values, color) {
  const ctx = fitCanvas(canvas);
  const { width, height } = canvas;
  ctx.clearRect(0, 0, width, height);
  const known = values.filter((v) => v !== null);
  if (known.length < 2) return;
  const max = niceMax(Math.max(...known));
  ctx.strokeStyle = color;
  ctx.lineWidth = devicePixelRatio;
  ctx.beginPath();
  let started = false;
  values.forEach((v, i) => {
    if (v === null) return;
    const x = (i / Math.max(1, values.length - 1)) * width;
    const y = height - (v / max) * (height - 2) - 1;
    if (started) ctx.lineTo(x, y);
    else ctx.moveTo(x, y);
    started = true;
  });
  ctx.stroke();
}
