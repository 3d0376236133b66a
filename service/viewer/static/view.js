// The compare view: the input ("before") under the result ("after"), a draggable wipe between
// them, a toggle, zoom (fit, 100 %: one preview pixel per screen pixel, the wheel) and pan.

export class CompareView {
  constructor(root) {
    this.root = root;
    this.stage = root.querySelector(".stage");
    this.before = root.querySelector("img.before");
    this.after = root.querySelector("img.after");
    this.handle = root.querySelector(".wipe");
    this.split = 0.5;
    this.mode = "wipe"; // wipe | before | after
    this.zoom = null; // null: fit
    this.pan = [0, 0];
    this.size = [0, 0];
    this.bind();
  }

  setSize(w, h) {
    if (w === this.size[0] && h === this.size[1]) return;
    this.size = [w, h];
    this.stage.style.width = `${w}px`;
    this.stage.style.height = `${h}px`;
    this.layout();
  }

  show(which, url) {
    const img = which === "before" ? this.before : this.after;
    if (img.dataset.url) URL.revokeObjectURL(img.dataset.url);
    img.dataset.url = url;
    img.src = url;
  }

  setMode(mode) {
    this.mode = mode;
    this.layout();
  }

  scale() {
    if (this.zoom !== null) return this.zoom;
    const [w, h] = this.size;
    if (!w || !h) return 1;
    const box = this.root.getBoundingClientRect();
    return Math.min(box.width / w, box.height / h);
  }

  layout() {
    const s = this.scale();
    const box = this.root.getBoundingClientRect();
    const [w, h] = this.size;
    const x = (box.width - w * s) / 2 + this.pan[0];
    const y = (box.height - h * s) / 2 + this.pan[1];
    this.stage.style.transform = `translate(${x}px, ${y}px) scale(${s})`;
    const cut = this.mode === "after" ? 0 : this.mode === "before" ? 100 : this.split * 100;
    this.after.style.clipPath = `inset(0 0 0 ${cut}%)`;
    this.handle.hidden = this.mode !== "wipe";
    this.handle.style.left = `${x + this.split * w * s}px`;
    this.root.dataset.mode = this.mode;
    this.root.classList.toggle("zoomed", s > 1.5);
  }

  setZoom(zoom) {
    this.zoom = zoom;
    this.pan = [0, 0];
    this.layout();
  }

  bind() {
    new ResizeObserver(() => this.layout()).observe(this.root);
    this.handle.addEventListener("pointerdown", (e) => {
      e.stopPropagation();
      this.handle.setPointerCapture(e.pointerId);
      const move = (m) => {
        const r = this.stage.getBoundingClientRect();
        this.split = Math.min(1, Math.max(0, (m.clientX - r.left) / r.width));
        this.layout();
      };
      this.handle.addEventListener("pointermove", move);
      this.handle.addEventListener("pointerup", () => this.handle.removeEventListener("pointermove", move), { once: true });
    });
    this.root.addEventListener("pointerdown", (e) => {
      if (e.target === this.handle) return;
      this.root.setPointerCapture(e.pointerId);
      const start = [e.clientX - this.pan[0], e.clientY - this.pan[1]];
      const move = (m) => {
        if (this.zoom === null) this.zoom = this.scale();
        this.pan = [m.clientX - start[0], m.clientY - start[1]];
        this.layout();
      };
      this.root.addEventListener("pointermove", move);
      this.root.addEventListener("pointerup", () => this.root.removeEventListener("pointermove", move), { once: true });
    });
    this.root.addEventListener("wheel", (e) => {
      e.preventDefault();
      const s = this.scale();
      const next = Math.min(16, Math.max(0.05, s * Math.exp(-e.deltaY * 0.0015)));
      const box = this.root.getBoundingClientRect();
      const cx = e.clientX - box.left - box.width / 2 - this.pan[0];
      const cy = e.clientY - box.top - box.height / 2 - this.pan[1];
      this.pan = [this.pan[0] - cx * (next / s - 1), this.pan[1] - cy * (next / s - 1)];
      this.zoom = next;
      this.layout();
    }, { passive: false });
  }
}
