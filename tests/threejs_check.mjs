// Run by tests/test_threejs.py with node, beside a copy of examples/threejs/arkit_player.js and a node_modules
// holding `three`:  node threejs_check.mjs SPEC.json
// SPEC.json: {"weights": out.json, "names": [names for the rule], "meshes": {mesh name: [morph target
// names]}, "times": [seconds], "bad": [JSON documents that are not ARKit-shaped]}. Builds the meshes (a
// small grid each, one morph target per name), drives them with the clip the player module builds, and
// prints one line "threejs_check: {...}": the rule's answers, matched, unmatched, each target's influence at
// each time (through a bare AnimationMixer and through ArkitPlayer), and the error of each bad document.
import { readFileSync } from "node:fs";
import * as THREE from "three";
import { ArkitPlayer, arkitClip, arkitName } from "./arkit_player.js";

const spec = JSON.parse(readFileSync(process.argv[2], "utf8"));
const weights = JSON.parse(readFileSync(spec.weights, "utf8"));

function avatar() {
  const root = new THREE.Group();
  for (const [name, targets] of Object.entries(spec.meshes)) {
    const geometry = new THREE.PlaneGeometry(1, 1, 4, 4);
    const count = geometry.attributes.position.count;
    geometry.morphAttributes.position = targets.map((target, i) => {
      const offsets = new THREE.Float32BufferAttribute(new Float32Array(count * 3), 3);
      offsets.setZ(i % count, 0.1);
      offsets.name = target;
      return offsets;
    });
    const mesh = new THREE.Mesh(geometry, new THREE.MeshBasicMaterial());
    mesh.name = name;
    mesh.updateMorphTargets();
    root.add(mesh);
  }
  return root;
}

function influences(root) {
  const out = {};
  root.traverse((object) => {
    if (!object.morphTargetDictionary) return;
    out[object.name] = Object.fromEntries(Object.entries(object.morphTargetDictionary)
      .map(([target, index]) => [target, object.morphTargetInfluences[index]]));
  });
  return out;
}

const root = avatar();
const { clip, matched, unmatched } = arkitClip(weights, root);
const mixer = new THREE.AnimationMixer(root);
const action = mixer.clipAction(clip);
action.setLoop(THREE.LoopOnce, 1);
action.clampWhenFinished = true;
action.play();
const quaternions = [];
const sampled = spec.times.map((t) => {
  mixer.setTime(t);
  quaternions.push(root.quaternion.toArray());
  return influences(root);
});

const other = avatar();
const player = new ArkitPlayer(other, weights);
player.play();
let clock = 0;
const played = spec.times.map((t) => { player.update(t - clock); clock = t; return influences(other); });

const errors = spec.bad.map((doc) => {
  try { arkitClip(doc, avatar()); return null; } catch (error) { return error.message; }
});
console.log("threejs_check: " + JSON.stringify({
  rule: spec.names.map(arkitName), matched, unmatched, tracks: clip.tracks.length, duration: clip.duration,
  sampled, played, player_unmatched: player.unmatched, errors, quaternions,
}));
