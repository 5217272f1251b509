// Load a .glb with three.js GLTFLoader in plain Node, play its first animation with
// AnimationMixer and print morph weights and the animated node's transform at given times.
// Usage: node three_sample.mjs FILE.glb '[t0, t1, ...]' [positions]
// Prints JSON {targetNames, times, weights: [[...]], position: [[x,y,z]], quaternion: [[x,y,z,w]]}
// and, with "positions", the CPU-morphed world-space vertex positions (Mesh.getVertexPosition,
// which applies morphTargetInfluences) per time as a flat [x0,y0,z0,x1,...] array.
import { readFileSync } from "node:fs";
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";

const [file, timesJson, extra] = process.argv.slice(2);
const times = JSON.parse(timesJson);
const buf = readFileSync(file);
const arrayBuffer = buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength);

const gltf = await new Promise((resolve, reject) =>
  new GLTFLoader().parse(arrayBuffer, "", resolve, reject),
);
let mesh = null;
gltf.scene.traverse((o) => {
  if (!mesh && o.isMesh && o.morphTargetInfluences) mesh = o;
});
if (!mesh) throw new Error("no mesh with morph targets");
// the animated node: the mesh itself, or its parent group when GLTFLoader wraps it
const node = gltf.scene.getObjectByName(gltf.parser.json.nodes[0].name) || mesh;
const clip = gltf.animations[0];
const mixer = new THREE.AnimationMixer(gltf.scene);
const action = mixer.clipAction(clip);
action.setLoop(THREE.LoopOnce, 1);
action.clampWhenFinished = true;
action.play();
const result = {
  targetNames: Object.keys(mesh.morphTargetDictionary).sort(
    (a, b) => mesh.morphTargetDictionary[a] - mesh.morphTargetDictionary[b],
  ),
  duration: clip.duration,
  times,
  weights: [],
  position: [],
  quaternion: [],
  points: [],
};
const v = new THREE.Vector3();
for (const t of times) {
  mixer.setTime(t);
  result.weights.push(Array.from(mesh.morphTargetInfluences));
  result.position.push(node.position.toArray());
  result.quaternion.push(node.quaternion.toArray());
  if (extra === "positions") {
    gltf.scene.updateMatrixWorld(true);
    const n = mesh.geometry.attributes.position.count;
    const pts = new Array(3 * n);
    for (let i = 0; i < n; i++) {
      mesh.getVertexPosition(i, v).applyMatrix4(mesh.matrixWorld);
      pts[3 * i] = v.x;
      pts[3 * i + 1] = v.y;
      pts[3 * i + 2] = v.z;
    }
    result.points.push(pts);
  }
}
process.stdout.write(JSON.stringify(result));
