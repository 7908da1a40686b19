// BoxCanvas: the wrist image on a canvas where a person drags a box or clicks a brick.
// Shared by the dashboard and the robot's box picker (same page, see dashboard.js), so the box a
// person draws is computed by one piece of code: normalised x0, y0, x1, y1 of the image, where the
// image spans [0, 1] in both axes (as the env's observation.bbox). Points outside the canvas are
// kept as they are (the server clips the box, or refuses one that misses the image).

const CLICK_PX = 4; // a drag shorter than this (CSS px) is a click

export class BoxCanvas {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {{onBox?: (box: number[]) => void, onClick?: (point: number[]) => void}} handlers
   */
  constructor(canvas, handlers = {}) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.handlers = handlers;
    this.image = null;
    this.box = null; // the box the policy will get (drawn yellow)
    this.hint = null; // another box to show (the target brick's projected box, white, dashed)
    this.drag = null; // {start: [x, y] css px, end: [x, y] css px} while dragging
    canvas.addEventListener("pointerdown", (e) => this._down(e));
    canvas.addEventListener("pointermove", (e) => this._move(e));
    canvas.addEventListener("pointerup", (e) => this._up(e));
    canvas.addEventListener("pointercancel", () => { this.drag = null; this.draw(); });
    this.draw();
  }

  /** Show an image (URL); resolves once it is drawn. */
  setImage(url) {
    return new Promise((resolve, reject) => {
      const img = new Image();
      img.onload = () => { this.image = img; this.draw(); resolve(); };
      img.onerror = () => reject(new Error(`could not load ${url}`));
      img.src = url;
    });
  }

  /** Boxes to overlay: `box` (yellow, what the policy gets) and `hint` (white dashed). */
  setBoxes(box, hint = null) {
    this.box = box;
    this.hint = hint;
    this.draw();
  }

  /** Normalised image coordinates of a pointer event. */
  toNormalised(event) {
    const rect = this.canvas.getBoundingClientRect();
    return [(event.clientX - rect.left) / rect.width, (event.clientY - rect.top) / rect.height];
  }

  _down(event) {
    if (event.button !== 0) return;
    this.canvas.setPointerCapture(event.pointerId); // keep the drag when the pointer leaves the canvas
    const p = this.toNormalised(event);
    this.drag = {start: p, end: p, startPx: [event.clientX, event.clientY]};
    this.draw();
  }

  _move(event) {
    if (!this.drag) return;
    this.drag.end = this.toNormalised(event);
    this.draw();
  }

  _up(event) {
    if (!this.drag) return;
    const drag = this.drag;
    drag.end = this.toNormalised(event);
    this.drag = null;
    const moved = Math.hypot(event.clientX - drag.startPx[0], event.clientY - drag.startPx[1]);
    if (moved < CLICK_PX) {
      this.draw();
      this.handlers.onClick?.(drag.end);
      return;
    }
    const [ax, ay] = drag.start;
    const [bx, by] = drag.end;
    const box = [Math.min(ax, bx), Math.min(ay, by), Math.max(ax, bx), Math.max(ay, by)];
    this.box = box;
    this.draw();
    this.handlers.onBox?.(box);
  }

  _rect(box, color, dashed) {
    const w = this.canvas.width, h = this.canvas.height;
    this.ctx.save();
    this.ctx.strokeStyle = color;
    this.ctx.lineWidth = 2;
    if (dashed) this.ctx.setLineDash([5, 4]);
    this.ctx.strokeRect(box[0] * w, box[1] * h, (box[2] - box[0]) * w, (box[3] - box[1]) * h);
    this.ctx.restore();
  }

  draw() {
    const {ctx, canvas} = this;
    ctx.fillStyle = "#222";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (this.image) {
      ctx.imageSmoothingEnabled = false; // show the 224 px pixels the policy sees
      ctx.drawImage(this.image, 0, 0, canvas.width, canvas.height);
    }
    if (this.hint) this._rect(this.hint, "#ffffff", true);
    if (this.box && !this.drag) this._rect(this.box, "#ffdc00", false);
    if (this.drag) {
      const [ax, ay] = this.drag.start;
      const [bx, by] = this.drag.end;
      this._rect([Math.min(ax, bx), Math.min(ay, by), Math.max(ax, bx), Math.max(ay, by)], "#00e5ff", true);
    }
  }
}
