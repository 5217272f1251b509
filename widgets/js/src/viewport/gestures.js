// The one gesture client: every pointer interaction that edits the model (a marker drag
// or a brush stroke, which Python routes to the current tool or to a panel's hook) speaks this protocol with widgets/viewport/gestures.py:
//
//   front end -> Python  {type: kind, phase: "start"|"move"|"end"|"cancel", gesture, seq, ...body}
//   Python -> front end  {type: kind + "_ack", seq, phase, version, kernel_ms[, tint_version]}
//                        {type: "patch", seq, ...}  (the geometry of that message: an early ack)
//                        {type: kind + "_cancel"[, gesture]}  (the kernel ended the gesture)
//
// ONE message is in flight: new input only marks the client dirty; the tool's body() (the
// newest pointer position, or the dabs queued since) goes out when the previous message's
// ack - or its geometry patch - arrives, so a slow kernel sees fewer, not queued-up,
// updates. A message lost for LOST_MS no longer blocks. "end" keeps the edits (one undo
// step), "cancel" (Escape) puts them back.

const LOST_MS = 2000;
let clientIds = 0;

export class GestureClient {
  // kind: "drag" | "stroke" (the message type). options:
  //   body(phase) -> object   what the next message carries (called when it is sent)
  //   measure(phase, body)    -> stat fields or null: record timing for this message
  //   onStat(stat)            an acked message's timing {kind, seq, input, send, ack, kernel, version}
  //   onCancel()              the kernel ended the gesture (its edits are kept or reverted)
  constructor(model, store, kind, options) {
    this.model = model;
    this.store = store;
    this.kind = kind;
    this.options = options;
    this.prefix = `${kind}-${(clientIds += 1)}-${Math.random().toString(36).slice(2, 7)}`;
    this.count = 0;
    this.active = null; // {gesture, inFlight, sentAt, dirty, inputTime}
    this.pending = new Map(); // seq -> stat of a message waiting for its ack
  }

  get open() {
    return this.active !== null;
  }

  begin(inputTime) {
    if (this.active) this.end();
    this.count += 1;
    this.active = { gesture: `${this.prefix}-${this.count}`, inFlight: 0, sentAt: 0, dirty: false, inputTime };
    this.send("start");
  }

  // New input is ready (the tool's body() will read it): sent now unless a message is in flight.
  update(inputTime) {
    const a = this.active;
    if (!a) return;
    a.dirty = true;
    if (inputTime != null) a.inputTime = inputTime;
    this.flush();
  }

  flush() {
    const a = this.active;
    if (!a || !a.dirty) return;
    if (a.inFlight && performance.now() - a.sentAt < LOST_MS) return;
    this.send("move");
  }

  end() {
    if (!this.active) return;
    this.send("end");
    this.active = null;
  }

  cancel() {
    if (!this.active) return;
    this.send("cancel");
    this.active = null;
  }

  send(phase) {
    const a = this.active;
    const seq = this.store.nextSeq();
    const body = phase === "cancel" ? {} : this.options.body(phase);
    a.dirty = false;
    this.model.send({ type: this.kind, phase, gesture: a.gesture, seq, ...body });
    if (phase === "start" || phase === "move") {
      a.inFlight = seq;
      a.sentAt = performance.now();
      const extra = this.options.measure ? this.options.measure(phase, body) : null;
      if (extra) {
        this.pending.set(seq, { kind: this.kind, seq, input: a.inputTime, send: a.sentAt, ...extra });
      }
    }
  }

  // An ack (or the geometry patch carrying its seq) from Python.
  onAck(content) {
    const st = this.pending.get(content.seq);
    if (st) {
      this.pending.delete(content.seq);
      st.ack = performance.now();
      st.kernel = content.kernel_ms != null ? content.kernel_ms : null;
      st.version = content.version;
      if (this.options.onStat) this.options.onStat(st);
    }
    const a = this.active;
    if (a && a.inFlight === content.seq) {
      a.inFlight = 0;
      this.flush();
    }
  }

  // Python ended the gesture (an error, the dragged marker removed, another widget's edit).
  onCancel(content) {
    const a = this.active;
    if (!a || (content && content.gesture != null && content.gesture !== a.gesture)) return;
    this.active = null;
    if (this.options.onCancel) this.options.onCancel();
  }
}
