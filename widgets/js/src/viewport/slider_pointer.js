// A slider drag ends when the person lets go, and the page says so: a pointer pressed on any
// ipywidgets slider of the page sends {type: "slider_pointer", phase: "down"}, its release
// {phase: "up"} (widgets/_threading.py: SliderPointer ends the drag's undo step). The kernel
// must hear the release after the slider's last value, so "up" waits until the slider's own
// handlers ran (they set the final value on release) and every widget state the page holds
// back has gone out: ipywidgets sends one state message per model at a time and buffers the
// next in the model's _msg_buffer until the kernel answers (widget.ts, WidgetModel.sync).
// Messages then reach the kernel in the order they were sent.

const SLIDER = ".widget-slider, .widget-hslider, .widget-vslider, .noUi-target";
const MAX_WAIT_MS = 10000;

async function buffered(manager) {
  const all = Object.values((manager && manager._models) || {});
  const models = await Promise.all(all.map((p) => Promise.resolve(p).catch(() => null)));
  return models.some((m) => m && m._msg_buffer);
}

async function afterBufferedState(manager) {
  const t0 = performance.now();
  while ((await buffered(manager)) && performance.now() - t0 < MAX_WAIT_MS) {
    await new Promise((resolve) => setTimeout(resolve, 16));
  }
}

// Watch the page's pointer on sliders for `model` (a viewport); returns the function that stops.
export function watchSliderPointer(model) {
  let down = false;
  const send = (phase) => {
    try {
      model.send({ type: "slider_pointer", phase });
    } catch (e) {
      // the widget was closed: nobody to tell
    }
  };
  const onDown = (e) => {
    if (!(e.target instanceof Element) || !e.target.closest(SLIDER)) return;
    down = true;
    send("down");
  };
  const onUp = () => {
    if (!down) return;
    down = false;
    // setTimeout: after this event's dispatch, so the slider's release handler ran first
    setTimeout(() => afterBufferedState(model.widget_manager).then(() => send("up")), 0);
  };
  // capture: a slider's own handlers may stop the event's propagation
  window.addEventListener("pointerdown", onDown, true);
  window.addEventListener("pointerup", onUp, true);
  window.addEventListener("pointercancel", onUp, true);
  return () => {
    window.removeEventListener("pointerdown", onDown, true);
    window.removeEventListener("pointerup", onUp, true);
    window.removeEventListener("pointercancel", onUp, true);
  };
}
