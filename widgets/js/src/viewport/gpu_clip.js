// Playback in the browser (Python side: GpuSync.prepare_clip in widgets/viewport/gpu.py and
// widgets/timeline/playback.py): the parameters of every frame of the timeline
// (_gpu_clip: frames x width f32, _gpu_clip_meta {version, frames, fps, start, width}),
// played from the browser's own clock between {type: "gpu_play", time, end, loop} and
// {type: "gpu_stop"}. Methods mixed into the Store (./sync.js).
import { typed } from "./util.js";

// The same rule as browser_time() in widgets/timeline/playback.py.
export function clipTime(t0, elapsed, start, end, loop) {
  const t = t0 + elapsed;
  if (t <= end) return t;
  if (!loop || !(end > start)) return end;
  return start + ((t - start) % (end - start));
}

export const clipMethods = {
  loadClip() {
    const meta = this.model.get("_gpu_clip_meta") || {};
    if (!meta.version || meta.version === (this.clip && this.clip.version)) return;
    const data = typed(this.model.get("_gpu_clip"), Float32Array);
    if (!data || data.length !== meta.frames * meta.width) { this.clip = null; return; }
    this.clip = { ...meta, data: new Float32Array(data) };
  },

  playClip(msg) {
    this.loadClip();
    if (!this.clip || !this.gpuMode) return;
    this.clipPlay = {
      t0: Number(msg.time), end: Number(msg.end), loop: !!msg.loop,
      wall0: performance.now(), frame: -1, shown: 0,
    };
    for (const v of this.views) v.clipStarted?.();
    const tick = () => {
      const p = this.clipPlay;
      if (!p) return;
      const c = this.clip;
      const t = clipTime(p.t0, (performance.now() - p.wall0) / 1000, c.start, p.end, p.loop);
      const f = Math.min(Math.max(Math.round((t - c.start) * c.fps), 0), c.frames - 1);
      if (f !== p.frame) {
        p.frame = f;
        p.time = c.start + f / c.fps;
        this.gpuParams = c.data.slice(f * c.width, (f + 1) * c.width);
        this.pageParamsChanged(); // ./gpu_local.js
      }
      p.raf = requestAnimationFrame(tick);
    };
    tick();
  },

  stopClip() {
    const p = this.clipPlay;
    if (!p) return;
    cancelAnimationFrame(p.raf);
    this.clipPlay = null;
    for (const v of this.views) v.clipStopped?.();
  },
};
