// What a rendered frame shows where it is not the sky, shared by babylon.html and three.html:
// `px` RGBA bytes of a w × h frame, `sky` the background's RGB bytes. Returns the share of the
// frame covered, the mean colour (0..1 per channel), the share of those pixels that are dark
// (luminance < 0.08), the share where green leads (g > r and g > b): grass that turned black
// or vanished fails the --green check on these; and the share that is white (every channel over
// 0.7, within 0.12 of each other): snow, which a [snow] scene's view must show.
window.frameStats = (px, w, h, sky) => {
  let covered = 0, dark = 0, green = 0, white = 0;
  const sum = [0, 0, 0];
  for (let i = 0; i < w * h * 4; i += 4) {
    const [r, g, b] = [px[i], px[i + 1], px[i + 2]];
    if (Math.abs(r - sky[0]) + Math.abs(g - sky[1]) + Math.abs(b - sky[2]) < 12) continue;
    covered++;
    sum[0] += r; sum[1] += g; sum[2] += b;
    if (0.2126 * r + 0.7152 * g + 0.0722 * b < 0.08 * 255) dark++;
    if (g > r && g > b) green++;
    if (Math.min(r, g, b) > 0.7 * 255 && Math.max(r, g, b) - Math.min(r, g, b) < 0.12 * 255) white++;
  }
  const n = Math.max(covered, 1);
  return { covered: covered / (w * h), mean: sum.map((v) => v / n / 255), dark: dark / n, green: green / n, white: white / n };
};
