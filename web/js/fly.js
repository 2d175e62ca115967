// Flying: WASD (and the arrows) move, Q/E or Shift/Space go down and up, dragging the mouse
// looks around, the wheel or the slider sets the speed. On a touch screen one finger looks and
// two fingers move (drag up to go forward). The camera lives in the URL's fragment,
// `#x,y,z,yaw,pitch` (degrees), so a view can be shared.

const KEYS = {
  KeyW: [0, 0, 1], ArrowUp: [0, 0, 1], KeyS: [0, 0, -1], ArrowDown: [0, 0, -1],
  KeyA: [-1, 0, 0], ArrowLeft: [-1, 0, 0], KeyD: [1, 0, 0], ArrowRight: [1, 0, 0],
  KeyE: [0, 1, 0], Space: [0, 1, 0], KeyQ: [0, -1, 0], ShiftLeft: [0, -1, 0], ShiftRight: [0, -1, 0],
};

export class Fly {
  constructor(camera, canvas, speedInput, speedLabel) {
    this.camera = camera;
    this.canvas = canvas;
    this.yaw = 0;
    this.pitch = 0;
    this.held = new Set();
    this.speedInput = speedInput;
    this.speedLabel = speedLabel;
    this.moved = true;
    this.lastFragment = '';
    this.touches = new Map();

    addEventListener('keydown', (e) => {
      if (e.target instanceof HTMLInputElement) return;
      if (KEYS[e.code]) {
        this.held.add(e.code);
        e.preventDefault();
      }
    });
    addEventListener('keyup', (e) => this.held.delete(e.code));
    addEventListener('blur', () => this.held.clear());
    canvas.addEventListener('pointerdown', (e) => {
      canvas.setPointerCapture(e.pointerId);
      this.touches.set(e.pointerId, { x: e.clientX, y: e.clientY });
      canvas.classList.add('looking');
    });
    canvas.addEventListener('pointermove', (e) => {
      const last = this.touches.get(e.pointerId);
      if (!last) return;
      const dx = e.clientX - last.x, dy = e.clientY - last.y;
      last.x = e.clientX;
      last.y = e.clientY;
      if (this.touches.size >= 2) {
        // Two fingers: move forward or back, half each finger's share.
        this.forward(-dy * this.speed * 0.01 / this.touches.size);
      } else {
        this.look(dx, dy);
      }
    });
    const up = (e) => {
      this.touches.delete(e.pointerId);
      if (this.touches.size === 0) canvas.classList.remove('looking');
    };
    canvas.addEventListener('pointerup', up);
    canvas.addEventListener('pointercancel', up);
    canvas.addEventListener('wheel', (e) => {
      e.preventDefault();
      speedInput.value = String(Math.min(100, Math.max(0, Number(speedInput.value) - Math.sign(e.deltaY) * 4)));
      this.showSpeed();
    }, { passive: false });
    speedInput.addEventListener('input', () => this.showSpeed());
    addEventListener('hashchange', () => this.fromFragment());
    this.showSpeed();
  }

  /** Metres per second: 1 to 1,000, logarithmic in the slider. */
  get speed() {
    return 10 ** (Number(this.speedInput.value) / 100 * 3);
  }

  showSpeed() {
    const s = this.speed;
    this.speedLabel.textContent = `${s < 10 ? s.toFixed(1) : Math.round(s)} m/s`;
  }

  look(dx, dy) {
    this.yaw -= dx * 0.004;
    this.pitch = Math.max(-1.55, Math.min(1.55, this.pitch - dy * 0.004));
    this.apply();
  }

  forward(distance) {
    const d = this.direction();
    this.camera.position.addScaledVector(d, distance);
    this.apply();
  }

  direction() {
    const c = Math.cos(this.pitch);
    return { x: -Math.sin(this.yaw) * c, y: Math.sin(this.pitch), z: -Math.cos(this.yaw) * c, isVector3: true };
  }

  /** Puts the camera at `eye`, looking at `target`. */
  lookAt(eye, target) {
    this.camera.position.set(eye[0], eye[1], eye[2]);
    const dx = target[0] - eye[0], dy = target[1] - eye[1], dz = target[2] - eye[2];
    this.yaw = Math.atan2(-dx, -dz);
    this.pitch = Math.atan2(dy, Math.hypot(dx, dz));
    this.apply();
  }

  /** Reads `#x,y,z,yaw,pitch`; false if the fragment holds no camera. */
  fromFragment() {
    const parts = location.hash.slice(1).split(',').map(Number);
    if (parts.length !== 5 || parts.some((v) => !Number.isFinite(v))) return false;
    if (location.hash === this.lastFragment) return true;
    this.camera.position.set(parts[0], parts[1], parts[2]);
    this.yaw = (parts[3] * Math.PI) / 180;
    this.pitch = (parts[4] * Math.PI) / 180;
    this.apply();
    return true;
  }

  apply() {
    this.camera.rotation.set(this.pitch, this.yaw, 0, 'YXZ');
    this.camera.updateMatrixWorld();
    this.moved = true;
  }

  /** Per frame: moves by the held keys; writes the fragment now and then. */
  update(dt, now) {
    if (this.held.size) {
      let x = 0, y = 0, z = 0;
      for (const k of this.held) {
        const [a, b, c] = KEYS[k];
        x += a; y += b; z += c;
      }
      const step = this.speed * dt;
      const d = this.direction();
      const right = { x: Math.cos(this.yaw), z: -Math.sin(this.yaw) };
      const p = this.camera.position;
      p.x += (d.x * z + right.x * x) * step;
      p.y += (d.y * z + y) * step;
      p.z += (d.z * z + right.z * x) * step;
      this.apply();
    }
    if (now - (this.fragmentAt || 0) > 250) {
      this.fragmentAt = now;
      const p = this.camera.position;
      const deg = (r) => ((r * 180) / Math.PI).toFixed(1);
      const fragment = `#${p.x.toFixed(2)},${p.y.toFixed(2)},${p.z.toFixed(2)},${deg(this.yaw)},${deg(this.pitch)}`;
      if (fragment !== this.lastFragment) {
        this.lastFragment = fragment;
        history.replaceState(null, '', fragment);
      }
    }
  }
}
