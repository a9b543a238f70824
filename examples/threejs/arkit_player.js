// ARKit-52 blend-shape weights (facegen's `out.json`, Audio2Face's JSON layout) played on any three.js avatar
// whose morph targets are named like ARKit's, in sync with the clip's sound.
//
//   const weights = await (await fetch("out.json")).json();
//   const player = new ArkitPlayer(gltf.scene, weights, { listener, audioBuffer });   // audio optional
//   console.log(player.unmatched);            // ARKit shapes no morph target stands for
//   button.onclick = () => player.play();     // starts the sound and the motion together
//   // each frame: player.update(clock.getDelta());
//
// Morph targets are matched by name with facegen's rule (facegen/arkit/names.py `arkit_name`; tests check this
// copy against it): case-insensitive, prefixes such as `blendShape1.`, `ARKit_`, `Face:` stripped, `_L`/`_R`
// read as Left/Right. Every mesh under the root with a matching target is driven (head, teeth, eyes, ...).
import * as THREE from "three";

// ARKit's 52 names in Live Link Face's order (facegen/arkit/names.py ARKIT_NAMES)
export const ARKIT_NAMES = [
  "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
  "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
  "eyeSquintRight", "eyeWideRight", "jawForward", "jawLeft", "jawRight", "jawOpen", "mouthClose",
  "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight", "mouthSmileLeft", "mouthSmileRight",
  "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
  "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
  "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
  "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
  "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight", "tongueOut",
];
const KEY = new Map(ARKIT_NAMES.map((n) => [n.toLowerCase(), n]));
const PREFIX = /^(?:.*[.:|/])|^(?:arkit|blendshape\d*|bs|facs)[_\-. ]+/i;

/** The ARKit shape a morph target called `name` stands for, or null. */
export function arkitName(name) {
  const key = name.trim().replace(PREFIX, "").replace(/(?:[_\-. ]|(?<=[a-z]))(L|R)$/, (_, side) => (side === "L" ? "Left" : "Right"));
  return KEY.get(key.replaceAll("_", "").toLowerCase()) ?? null;
}

/** Check an Audio2Face-layout JSON; throws an Error (one line) when it is not ARKit-shaped. */
export function checkWeights(weights) {
  const shape = "not an Audio2Face blend-shape JSON (exportFps, facsNames, weightMat [frames][shapes])";
  if (!weights || !Array.isArray(weights.facsNames) || !Array.isArray(weights.weightMat)) throw new Error(shape);
  const width = weights.facsNames.length;
  if (!(weights.exportFps > 0)) throw new Error(`${shape}: exportFps must be a positive number`);
  if (!weights.weightMat.length || weights.weightMat.some((row) => !Array.isArray(row) || row.length !== width)) {
    throw new Error(`${shape}: every weightMat row must hold ${width} weights`);
  }
  if (!weights.facsNames.some((n) => typeof n === "string" && arkitName(n))) {
    throw new Error("not ARKit-shaped: none of its facsNames is one of ARKit's 52 (eyeBlinkLeft ... tongueOut)");
  }
  return weights;
}

/**
 * A THREE.AnimationClip driving the ARKit-named morph targets under `root` from `weights` (the parsed JSON):
 * one NumberKeyframeTrack per matched target, times frame / exportFps, linear between frames.
 * Returns { clip, matched: {ARKit name: ["mesh/target", ...]}, unmatched: [ARKit names of the file no target
 * stands for] }.
 */
export function arkitClip(weights, root, name = "arkit") {
  checkWeights(weights);
  const column = new Map();
  weights.facsNames.forEach((n, i) => {
    const shape = arkitName(n);
    if (shape && !column.has(shape)) column.set(shape, i);
  });
  const times = Float32Array.from(weights.weightMat, (_, frame) => frame / weights.exportFps);
  const tracks = [];
  const matched = {};
  root.traverse((object) => {
    if (!object.morphTargetDictionary || !object.morphTargetInfluences) return;
    for (const [target, index] of Object.entries(object.morphTargetDictionary)) {
      const shape = arkitName(target);
      if (!shape || !column.has(shape)) continue;
      const values = Float32Array.from(weights.weightMat, (row) => row[column.get(shape)]);
      tracks.push(new THREE.NumberKeyframeTrack(`${object.uuid}.morphTargetInfluences[${index}]`, times, values));
      (matched[shape] ??= []).push(`${object.name}/${target}`);
    }
  });
  const unmatched = [...column.keys()].filter((shape) => !(shape in matched));
  const head = headTrack(weights, root, times);
  if (head) tracks.push(head);
  return { clip: new THREE.AnimationClip(name, -1, tracks), matched, unmatched, head: Boolean(head) };
}

/**
 * The head's motion of a facegen JSON (its "facegenHead": yaw, pitch, roll in degrees per frame, applied as
 * Ry(yaw) Rx(pitch) Rz(roll): three.js's Euler order "YXZ") as a QuaternionKeyframeTrack on `head` (default
 * the root: put the avatar's head under a group at its neck to turn it about the neck), or null.
 */
export function headTrack(weights, head, times) {
  const values = weights.facegenHead && weights.facegenHead.values;
  if (!Array.isArray(values) || values.length !== times.length) return null;
  const out = new Float32Array(values.length * 4);
  const euler = new THREE.Euler();
  const q = new THREE.Quaternion();
  const rad = Math.PI / 180;
  values.forEach(([yaw, pitch, roll], i) => {
    q.setFromEuler(euler.set(pitch * rad, yaw * rad, roll * rad, "YXZ"));
    q.toArray(out, i * 4);
  });
  return new THREE.QuaternionKeyframeTrack(`${head.uuid}.quaternion`, times, out);
}

/** The avatar, its ARKit clip and (optionally) the clip's sound, started together and kept in sync. */
export class ArkitPlayer {
  constructor(root, weights, { listener = null, audioBuffer = null } = {}) {
    const { clip, matched, unmatched } = arkitClip(weights, root);
    Object.assign(this, { clip, matched, unmatched });
    this.mixer = new THREE.AnimationMixer(root);
    this.action = this.mixer.clipAction(clip);
    this.action.setLoop(THREE.LoopOnce, 1);
    this.action.clampWhenFinished = true;
    this.sound = listener && audioBuffer ? new THREE.Audio(listener).setBuffer(audioBuffer) : null;
    this.start = null;
  }

  /** Start (or restart) the motion and the sound from the clip's first frame. */
  play() {
    this.action.reset().play();
    this.mixer.setTime(0);
    if (this.sound) {
      if (this.sound.isPlaying) this.sound.stop();
      this.sound.play();
      this.start = this.sound.context.currentTime;
    }
  }

  /** Advance: with sound, to the audio clock's time since play() (no drift); else by `delta` seconds. */
  update(delta) {
    if (this.sound && this.start !== null) this.mixer.setTime(this.sound.context.currentTime - this.start);
    else this.mixer.update(delta);
  }
}
