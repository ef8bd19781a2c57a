// The 3D replay of a workcell evaluation's summary.html.
//
// The page lists its episodes in window.WORKCELL_REPLAYS (each {name, glb: base64}, from
// replays/episode-SEED.js beside the page: a page opened from disk may load scripts but not
// fetch files). This viewer parses each binary glTF in memory, plays its animation, and lets
// the user orbit, pause, scrub and change speed. It reports what it does on the element
// #replay-status (data-state, data-time, data-errors), which the CI check reads.
//
// Bundled with three.js by scripts/fetch-viewer.sh into one classic script (no modules,
// no network at view time).

import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const errors = [];
// Errors that three.js logs instead of throwing count too.
const consoleError = console.error.bind(console);
console.error = (...args) => { errors.push(args.map(String).join(' ')); consoleError(...args); };

function decode(base64) {
  const text = atob(base64);
  const bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
  return bytes.buffer;
}

function start() {
  const root = document.getElementById('replay');
  const status = document.getElementById('replay-status');
  const replays = window.WORKCELL_REPLAYS || [];
  const report = (state, text) => {
    status.dataset.state = state;
    status.dataset.errors = String(errors.length);
    status.textContent = errors.length ? `${text} (errors: ${errors.join('; ')})` : text;
  };
  window.addEventListener('error', (e) => { errors.push(String(e.message)); report('error', 'error'); });
  if (!root || replays.length === 0) {
    if (status) report('empty', 'no 3D replay in this report (workcell evaluate --gltf N)');
    return;
  }

  const canvas = document.createElement('canvas');
  canvas.id = 'replay-canvas';
  root.appendChild(canvas);
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xdfe4ea);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 2.2));
  const sun = new THREE.DirectionalLight(0xffffff, 2.0);
  sun.position.set(3, 6, 2);
  scene.add(sun);
  const camera = new THREE.PerspectiveCamera(45, 16 / 9, 0.02, 100);
  const controls = new OrbitControls(camera, canvas);
  const clock = new THREE.Clock();
  const loader = new GLTFLoader();

  const select = document.getElementById('replay-episode');
  const play = document.getElementById('replay-play');
  const slider = document.getElementById('replay-time');
  const speed = document.getElementById('replay-speed');
  replays.forEach((r, i) => {
    const option = document.createElement('option');
    option.value = String(i);
    option.textContent = r.name;
    select.appendChild(option);
  });

  let current = null; // {gltf, mixer, duration}
  // `summary.html#t=4.2` opens the replay paused at 4.2 s (a moment to point someone at).
  const startAt = /(?:^#|&)t=([0-9.]+)/.exec(window.location.hash);
  let playing = !startAt;
  let frames = 0;
  let played = 0;

  // How many distinct colours the last frame shows on a 16 x 16 grid: a blank canvas has
  // one. The CI check reads it from #replay-status's data-colours.
  function colours() {
    const gl = renderer.getContext();
    const w = gl.drawingBufferWidth;
    const h = gl.drawingBufferHeight;
    const pixel = new Uint8Array(4);
    const seen = new Set();
    for (let i = 0; i < 16; i++) {
      for (let j = 0; j < 16; j++) {
        gl.readPixels(Math.floor((i + 0.5) * w / 16), Math.floor((j + 0.5) * h / 16), 1, 1,
          gl.RGBA, gl.UNSIGNED_BYTE, pixel);
        seen.add(`${pixel[0]},${pixel[1]},${pixel[2]}`);
      }
    }
    return seen.size;
  }

  function frame(object) {
    // Frame the robot and the human (the room is far larger). three.js drops the '/' of
    // node names ("robot/link1" becomes "robotlink1").
    const box = new THREE.Box3();
    object.traverse((node) => {
      if (/^(robot|human)/.test(node.name)) box.expandByObject(node);
    });
    if (box.isEmpty()) box.setFromObject(object);
    const centre = box.getCenter(new THREE.Vector3());
    const size = box.getSize(new THREE.Vector3()).length();
    // From the open side of the room: the walls stand at the cell's -x and -y (glTF's +z).
    camera.position.copy(centre).add(new THREE.Vector3(0.75, 0.5, -0.75).multiplyScalar(size));
    controls.target.copy(centre);
    controls.update();
  }

  function load(index) {
    if (current) scene.remove(current.gltf.scene);
    current = null;
    report('loading', `loading ${replays[index].name}`);
    loader.parse(decode(replays[index].glb), '', (gltf) => {
      scene.add(gltf.scene);
      const mixer = new THREE.AnimationMixer(gltf.scene);
      let duration = 0;
      for (const clip of gltf.animations) {
        mixer.clipAction(clip).play();
        duration = Math.max(duration, clip.duration);
      }
      current = { gltf, mixer, duration };
      slider.max = String(duration);
      if (startAt) mixer.setTime(Math.min(Number(startAt[1]), duration));
      play.textContent = playing ? 'pause' : 'play';
      frame(gltf.scene);
    }, (e) => { errors.push(String(e && e.message ? e.message : e)); report('error', 'the replay did not load'); });
  }

  function resize() {
    const width = root.clientWidth || 960;
    const height = Math.round(width * 9 / 16);
    renderer.setSize(width, height, false);
    canvas.style.width = `${width}px`;
    canvas.style.height = `${height}px`;
    camera.aspect = width / height;
    camera.updateProjectionMatrix();
  }

  select.addEventListener('change', () => load(Number(select.value)));
  play.addEventListener('click', () => { playing = !playing; play.textContent = playing ? 'pause' : 'play'; });
  slider.addEventListener('input', () => { if (current) current.mixer.setTime(Number(slider.value)); });
  window.addEventListener('resize', resize);
  resize();
  load(0);

  renderer.setAnimationLoop(() => {
    const dt = clock.getDelta();
    if (current) {
      if (playing) {
        const step = dt * Number(speed.value || 1);
        current.mixer.update(step);
        played += step;
        // Loop: back to the start, keeping the overshoot.
        if (current.mixer.time > current.duration && current.duration > 0) {
          current.mixer.setTime(current.mixer.time % current.duration);
        }
      }
      // Seconds of episode played since the page opened (the replay loops, so its time
      // alone does not tell whether it plays).
      status.dataset.played = played.toFixed(3);
      const t = current.mixer.time;
      slider.value = String(t);
      status.dataset.time = t.toFixed(3);
      report(playing ? 'playing' : 'paused',
        `${replays[Number(select.value)].name}: t = ${t.toFixed(2)} of ${current.duration.toFixed(2)} s`);
    }
    controls.update();
    renderer.render(scene, camera);
    frames += 1;
    status.dataset.frames = String(frames);
    if (current && frames % 30 === 1) status.dataset.colours = String(colours());
  });
}

if (document.readyState === 'loading') {
  document.addEventListener('DOMContentLoaded', start);
} else {
  start();
}
