// Expression chips: one per name in `expressions`, draggable (HTML5 drag with the name as
// application/x-fwb-expression) onto the tracks or the ruler, where the drop keys that
// expression ({type: "key_expression", name, time}). When `_thumbnails` (name -> PNG
// bytes, arriving as binary buffers) has pictures, the strip is a one-row, horizontally
// scrolling gallery of small thumbnails with the name under each; without any, the chips
// are text. Methods of TimelineView (./view.js).

import { THUMB } from "./style.js";
import { el } from "./toolbar.js";

// PNG bytes of a `_thumbnails` value: a DataView (ipywidgets' binary buffers) or any view
function asBytes(v) {
  if (!v) return null;
  if (v instanceof Uint8Array) return v;
  if (v instanceof ArrayBuffer) return new Uint8Array(v);
  if (ArrayBuffer.isView(v)) return new Uint8Array(v.buffer, v.byteOffset, v.byteLength);
  return null;
}

function sameBytes(a, b) {
  if (a.length !== b.length) return false;
  for (let i = 0; i < a.length; i++) if (a[i] !== b[i]) return false;
  return true;
}

export const chipMethods = {
  // HTML5 drop of an expression chip onto the main canvas
  bindDrop() {
    const c = this.canvas;
    this.on(c, "dragover", (e) => this.onDragOver(e));
    this.on(c, "dragleave", () => {
      this.dropTime = null;
      this.requestDraw();
    });
    this.on(c, "drop", (e) => this.onDrop(e));
  },

  // object URLs of the chip pictures, remade only for PNGs whose bytes changed
  syncThumbs() {
    const raw = this.model.get("_thumbnails") || {};
    if (raw === this.thumbsRaw) return false;
    this.thumbsRaw = raw;
    let changed = false;
    const seen = new Set();
    for (const [name, value] of Object.entries(raw)) {
      const bytes = asBytes(value);
      if (!bytes || !bytes.length) continue;
      seen.add(name);
      const old = this.thumbs.get(name);
      if (old && sameBytes(old.bytes, bytes)) continue;
      if (old) URL.revokeObjectURL(old.url);
      const copy = bytes.slice(); // the message buffer may be reused
      this.thumbs.set(name, { bytes: copy, url: URL.createObjectURL(new Blob([copy], { type: "image/png" })) });
      changed = true;
    }
    for (const [name, { url }] of [...this.thumbs]) {
      if (seen.has(name)) continue;
      URL.revokeObjectURL(url);
      this.thumbs.delete(name);
      changed = true;
    }
    return changed;
  },

  syncChips() {
    const thumbsChanged = this.syncThumbs();
    const names = this.model.get("expressions") || [];
    const saved = new Set(this.model.get("_saved_expressions") || []);
    const key = JSON.stringify([names, [...saved]]);
    if (key === this.chipsKey && !thumbsChanged) return;
    this.chipsKey = key;
    const pictures = names.some((n) => this.thumbs.has(n));
    this.chips.classList.toggle("fwb-tl-thumbs", pictures);
    this.chips.replaceChildren(el("span", { class: "fwb-tl-chips-label", text: "Drag onto the timeline:" }));
    let shown = 0;
    for (const n of names) {
      const kind = saved.has(n) ? "saved expression" : "blendshape";
      const chip = el("span", {
        class: "fwb-tl-chip" + (saved.has(n) ? " fwb-saved" : "") + (pictures ? " fwb-tl-thumb" : ""),
        draggable: "true",
        "data-name": n,
        title: `${kind} ${n}: drag onto the timeline to key it`,
      });
      let img = null;
      if (pictures) {
        const th = this.thumbs.get(n);
        if (th) {
          // the chip is dragged, not the picture (whose own drag would carry its URL)
          img = el("img", { src: th.url, alt: n, draggable: "false", width: THUMB, height: THUMB });
          shown += 1;
        }
        chip.append(
          img || el("span", { class: "fwb-tl-noimg", text: saved.has(n) ? "★" : n.slice(0, 1) }),
          el("span", { class: "fwb-tl-chip-name", text: saved.has(n) ? `★ ${n}` : n }),
        );
      } else {
        chip.textContent = n;
      }
      chip.addEventListener("dragstart", (e) => {
        e.dataTransfer.setData("application/x-fwb-expression", n);
        e.dataTransfer.setData("text/plain", n);
        e.dataTransfer.effectAllowed = "copy";
        if (img) e.dataTransfer.setDragImage(img, THUMB / 2, THUMB / 2);
      });
      this.chips.appendChild(chip);
    }
    this.chips.setAttribute("data-thumbs", String(shown));
  },

  acceptsDrop(e) {
    const types = Array.from((e.dataTransfer && e.dataTransfer.types) || []);
    return types.includes("application/x-fwb-expression") || types.includes("text/plain");
  },

  onDragOver(e) {
    if (!this.acceptsDrop(e) || !this.geom) return;
    e.preventDefault();
    e.dataTransfer.dropEffect = "copy";
    const [x] = this.localXY(e, this.canvas);
    this.dropTime = this.snap(Math.max(this.geom.xt(x), this.state().view[0]));
    this.requestDraw();
  },

  onDrop(e) {
    if (!this.acceptsDrop(e) || !this.geom) return;
    e.preventDefault();
    const name =
      e.dataTransfer.getData("application/x-fwb-expression") || e.dataTransfer.getData("text/plain");
    const [x] = this.localXY(e, this.canvas);
    const t = this.snap(Math.max(this.geom.xt(x), this.state().view[0]));
    this.dropTime = null;
    this.requestDraw();
    if (name) this.send({ type: "key_expression", name, time: t });
  },
};
