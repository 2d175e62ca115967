// Image comparison for the browser tests, the same measures as `horizon_impostor::compare`:
// PSNR over RGB (capped at 100 dB for identical images) and SSIM over luma (Wang et al. 2004,
// an 11x11 Gaussian window of sigma 1.5, K1 0.01, K2 0.03, L 255).

export function psnr(a, b) {
  let sum = 0;
  let n = 0;
  for (let i = 0; i < a.data.length; i += 4) {
    for (let c = 0; c < 3; c++) {
      const d = a.data[i + c] - b.data[i + c];
      sum += d * d;
      n++;
    }
  }
  if (sum === 0) return 100;
  return Math.min(100, 10 * Math.log10((255 * 255) / (sum / n)));
}

function luma(img) {
  const out = new Float64Array(img.width * img.height);
  for (let p = 0; p < out.length; p++) {
    const i = p * 4;
    out[p] = 0.299 * img.data[i] + 0.587 * img.data[i + 1] + 0.114 * img.data[i + 2];
  }
  return out;
}

function blur(src, w, h) {
  const radius = 5;
  const kernel = [];
  let total = 0;
  for (let k = -radius; k <= radius; k++) {
    const v = Math.exp(-(k * k) / (2 * 1.5 * 1.5));
    kernel.push(v);
    total += v;
  }
  for (let k = 0; k < kernel.length; k++) kernel[k] /= total;
  const tmp = new Float64Array(w * h);
  const out = new Float64Array(w * h);
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) {
      let s = 0;
      for (let k = -radius; k <= radius; k++) s += kernel[k + radius] * src[y * w + Math.min(w - 1, Math.max(0, x + k))];
      tmp[y * w + x] = s;
    }
  }
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) {
      let s = 0;
      for (let k = -radius; k <= radius; k++) s += kernel[k + radius] * tmp[Math.min(h - 1, Math.max(0, y + k)) * w + x];
      out[y * w + x] = s;
    }
  }
  return out;
}

export function ssim(a, b) {
  const { width: w, height: h } = a;
  const x = luma(a), y = luma(b);
  const mul = (p, q) => p.map((v, i) => v * q[i]);
  const mx = blur(x, w, h), my = blur(y, w, h);
  const sxx = blur(mul(x, x), w, h), syy = blur(mul(y, y), w, h), sxy = blur(mul(x, y), w, h);
  const c1 = (0.01 * 255) ** 2, c2 = (0.03 * 255) ** 2;
  let sum = 0;
  for (let i = 0; i < w * h; i++) {
    const vx = sxx[i] - mx[i] * mx[i], vy = syy[i] - my[i] * my[i], cxy = sxy[i] - mx[i] * my[i];
    sum += ((2 * mx[i] * my[i] + c1) * (2 * cxy + c2)) / ((mx[i] ** 2 + my[i] ** 2 + c1) * (vx + vy + c2));
  }
  return sum / (w * h);
}

/** Share of pixels that differ from `background` by more than 8 levels in some channel. */
export function drawnShare(img, background) {
  let drawn = 0;
  for (let i = 0; i < img.data.length; i += 4) {
    if ([0, 1, 2].some((c) => Math.abs(img.data[i + c] - background[c]) > 8)) drawn++;
  }
  return drawn / (img.data.length / 4);
}
