// Sizes, colours and the stylesheet of the timeline (no state).

export const GUTTER = 150; // px: track labels
export const RULER = 30; // px: time ruler height
export const ROW = 22; // px: one track row
export const RIGHT_PAD = 12;
export const CURVE_H = 150;
export const KEY_R = 6; // diamond half size
export const HANDLE_R = 5;
export const DRAG_START_PX = 3;
export const THUMB = 48; // px: chip picture (CSS size; the PNGs are larger, sharp on HiDPI)

export const COLORS = {
  bg: "#fbfbfc",
  ruler: "#eceef2",
  rowAlt: "#f3f4f7",
  rowSel: "#e3ecfb",
  grid: "#d5d9e0",
  gridMajor: "#b4bac4",
  text: "#333a44",
  textDim: "#6b7380",
  key: "#e0a526",
  keyStep: "#8c8c8c",
  keyLinear: "#3f9b5a",
  keySel: "#1f6fe5",
  keyStroke: "#5a4310",
  playhead: "#d63a3a",
  curve: "#1f6fe5",
  handleAuto: "#7c8898",
  handleUser: "#c2410c",
  drop: "#1f6fe5",
};

const CSS = `
.fwb-timeline { font: 12px/1.3 system-ui, -apple-system, "Segoe UI", sans-serif; color: ${COLORS.text};
  border: 1px solid #d0d4da; border-radius: 4px; background: #fff; outline: none; user-select: none;
  display: flex; flex-direction: column; gap: 4px; padding: 4px; box-sizing: border-box; width: 100%; }
.fwb-timeline:focus { border-color: #7aa7f0; }
.fwb-tl-toolbar { display: flex; flex-wrap: wrap; align-items: center; gap: 4px; }
.fwb-tl-toolbar button { font: inherit; padding: 2px 8px; border: 1px solid #c3c8d0; border-radius: 3px;
  background: #f6f7f9; cursor: pointer; }
.fwb-tl-toolbar button:hover { background: #eceff3; }
.fwb-tl-toolbar button:disabled { opacity: .45; cursor: default; }
.fwb-tl-toolbar button.fwb-on { background: #dbe7fb; border-color: #7aa7f0; }
.fwb-tl-toolbar label { display: inline-flex; align-items: center; gap: 3px; }
.fwb-tl-toolbar input[type=number] { width: 52px; font: inherit; }
.fwb-tl-toolbar select { font: inherit; }
.fwb-tl-sep { width: 1px; height: 18px; background: #d0d4da; margin: 0 3px; }
.fwb-tl-status { margin-left: auto; color: ${COLORS.textDim}; white-space: nowrap; overflow: hidden;
  text-overflow: ellipsis; max-width: 46%; }
.fwb-tl-status.fwb-err { color: #b42318; }
.fwb-tl-chips { display: flex; flex-wrap: wrap; gap: 3px; max-height: 42px; overflow-y: auto; }
.fwb-tl-chip { padding: 1px 6px; border-radius: 9px; background: #eef1f5; border: 1px solid #d3d8df;
  cursor: grab; font-size: 11px; }
.fwb-tl-chip.fwb-saved { background: #fdf1d8; border-color: #e8c880; font-weight: 600; }
.fwb-tl-chips-label { color: ${COLORS.textDim}; font-size: 11px; padding: 1px 2px; }
.fwb-tl-chips.fwb-tl-thumbs { flex-wrap: nowrap; max-height: none; overflow-x: auto; overflow-y: hidden;
  align-items: stretch; padding-bottom: 2px; }
.fwb-tl-thumbs .fwb-tl-chips-label { align-self: center; flex: 0 0 52px; white-space: normal; }
.fwb-tl-chip.fwb-tl-thumb { flex: 0 0 auto; display: flex; flex-direction: column; align-items: center;
  gap: 1px; width: ${THUMB + 8}px; padding: 2px 1px 1px; border-radius: 4px; box-sizing: border-box; }
.fwb-tl-chip.fwb-tl-thumb:hover { border-color: #7aa7f0; }
.fwb-tl-thumb img, .fwb-tl-thumb .fwb-tl-noimg { display: block; width: ${THUMB}px; height: ${THUMB}px;
  border-radius: 3px; background: #fff; pointer-events: none; }
.fwb-tl-thumb .fwb-tl-noimg { display: flex; align-items: center; justify-content: center;
  color: ${COLORS.textDim}; font-size: 18px; background: #e4e7ec; }
.fwb-tl-chip-name { max-width: ${THUMB + 6}px; overflow: hidden; text-overflow: ellipsis; white-space: nowrap;
  font-size: 10px; line-height: 12px; }
.fwb-tl-canvas, .fwb-tl-curve-canvas { display: block; width: 100%; touch-action: none; }
.fwb-tl-curve-box { border-top: 1px solid #e2e5ea; }
.fwb-tl-head { display: flex; flex-wrap: wrap; align-items: center; gap: 8px; }
.fwb-tl-head label { display: inline-flex; align-items: center; gap: 3px; }
.fwb-tl-head input[type=range] { width: 96px; }
.fwb-tl-head button { font: inherit; padding: 2px 8px; border: 1px solid #c3c8d0; border-radius: 3px;
  background: #f6f7f9; cursor: pointer; }
.fwb-tl-head button:hover { background: #eceff3; }
.fwb-tl-deg { min-width: 36px; text-align: right; color: ${COLORS.textDim}; font-variant-numeric: tabular-nums; }
.fwb-tl-head-label { color: ${COLORS.textDim}; }
`;

// The stylesheet, once per page (every timeline on the page shares it).
export function injectCss() {
  if (document.getElementById("fwb-timeline-css")) return;
  const s = document.createElement("style");
  s.id = "fwb-timeline-css";
  s.textContent = CSS;
  document.head.appendChild(s);
}
