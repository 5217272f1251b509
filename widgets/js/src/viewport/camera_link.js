// Linked cameras: views whose widget has the same non-empty `camera_group` orbit and zoom
// together (the Rig tab's template and target views). Everything stays in the browser:
// an orbit in one view moves the others' cameras directly, no kernel message.
//
// What is shared is the view seen from the face: the camera's direction from its orbit
// target and its up vector in the FACE frame (x = subject's left, y = up, z = front; a
// "+z"-up model maps world (x, y, z) to face (x, z, -y)) and the zoom as a multiple of
// the distance that frames the view's own neutral mesh. So two faces of different size,
// units and up axis are seen from the same side at the same relative size; each keeps its
// own orbit centre (pan is not shared). data-camera = "dx,dy,dz,zoom" (face frame) after
// every change is the test hook.
// Methods mixed into View.
import * as THREE from "three";

const GROUPS = (globalThis.__fwbCameraGroups ||= new Map());

function toFace(view, v) {
  return view.model.get("_up_axis") === "+z" ? new THREE.Vector3(v.x, v.z, -v.y) : v.clone();
}

function toWorld(view, f) {
  return view.model.get("_up_axis") === "+z" ? new THREE.Vector3(f.x, -f.z, f.y) : f.clone();
}

export const cameraLinkMethods = {
  joinCameraGroup() {
    this.leaveCameraGroup();
    const group = this.model.get("camera_group") || "";
    this.cameraGroup = group;
    if (!group) return;
    if (!GROUPS.has(group)) GROUPS.set(group, new Set());
    GROUPS.get(group).add(this);
  },

  leaveCameraGroup() {
    const set = this.cameraGroup ? GROUPS.get(this.cameraGroup) : null;
    if (set) {
      set.delete(this);
      if (!set.size) GROUPS.delete(this.cameraGroup);
    }
    this.cameraGroup = "";
  },

  cameraState() {
    const offset = this.camera.position.clone().sub(this.controls.target);
    const dist = offset.length();
    return {
      dir: toFace(this, offset.normalize()),
      up: toFace(this, this.camera.up),
      zoom: this.frameDist ? dist / this.frameDist : 1,
    };
  },

  applyCameraState(s) {
    if (!this.renderer || !this.framed || !this.frameDist) return;
    const dist = s.zoom * this.frameDist;
    this.camera.up.copy(toWorld(this, s.up));
    this.camera.position.copy(this.controls.target).addScaledVector(toWorld(this, s.dir), dist);
    this.camera.near = Math.max(dist / 100, 1e-4);
    this.camera.far = dist * 100;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.userCamera = true;
    this.markCamera(s);
    this.requestRender(false);
  },

  // After the person moved this view's camera: the others in the group follow.
  broadcastCamera() {
    const set = this.cameraGroup ? GROUPS.get(this.cameraGroup) : null;
    const s = this.cameraState();
    this.markCamera(s);
    if (!set) return;
    for (const other of set) if (other !== this) other.applyCameraState(s);
  },

  markCamera(s) {
    const r = (x) => (Math.round(x * 1000) / 1000).toString();
    this.el.setAttribute("data-camera", [s.dir.x, s.dir.y, s.dir.z, s.zoom].map(r).join(","));
  },
};
