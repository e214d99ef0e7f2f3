//! The rasteriser: a panel of RGB pixels with a depth buffer, filled triangles with
//! a depth test, thick lines that show through the surface faded where it hides them,
//! rectangles and text. Pixel centres are at `(x + 0.5, y + 0.5)`; depth grows away
//! from the viewer.

use super::font;

/// An RGB colour.
pub(crate) type Rgb = [u8; 3];

/// A rectangle of pixels with its depth buffer.
#[derive(Clone)]
pub(crate) struct Panel {
    pub w: usize,
    pub h: usize,
    pub rgb: Vec<u8>,
    z: Vec<f32>,
}

impl Panel {
    /// A panel filled with `bg`, every depth at infinity.
    pub fn new(w: usize, h: usize, bg: Rgb) -> Panel {
        Panel {
            w,
            h,
            rgb: bg.repeat(w * h),
            z: vec![f32::INFINITY; w * h],
        }
    }

    /// A panel filled with `bg` without a depth buffer, for rectangles, text and
    /// copies only: a triangle or line drawn on it draws nothing.
    pub fn flat(w: usize, h: usize, bg: Rgb) -> Panel {
        Panel {
            w,
            h,
            rgb: bg.repeat(w * h),
            z: Vec::new(),
        }
    }

    #[inline]
    fn put(&mut self, i: usize, c: Rgb) {
        self.rgb[3 * i..3 * i + 3].copy_from_slice(&c);
    }

    #[inline]
    fn blend(&mut self, i: usize, c: Rgb, alpha: f32) {
        for (k, &ck) in c.iter().enumerate() {
            let o = self.rgb[3 * i + k] as f32;
            self.rgb[3 * i + k] = (o + (ck as f32 - o) * alpha).round() as u8;
        }
    }

    /// Fills a triangle of screen points `(x, y, depth)` with one colour where it is
    /// nearer than what is drawn.
    pub fn triangle(&mut self, v: [[f32; 3]; 3], c: Rgb) {
        if self.z.len() != self.w * self.h {
            return; // a flat panel
        }
        let [[x0, y0, z0], [x1, y1, z1], [x2, y2, z2]] = v;
        let area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
        if !area.is_finite() || area.abs() <= 1e-12 {
            return; // edge-on, or not finite
        }
        let (w, h) = (self.w as f32, self.h as f32);
        let min_x = x0.min(x1).min(x2).max(0.0);
        let max_x = x0.max(x1).max(x2).min(w - 0.5);
        let min_y = y0.min(y1).min(y2).max(0.0);
        let max_y = y0.max(y1).max(y2).min(h - 0.5);
        if !(min_x <= max_x && min_y <= max_y) {
            return;
        }
        // pixels whose centre may be inside
        let px0 = ceil_index(min_x - 0.5);
        let px1 = floor_index(max_x - 0.5);
        let py0 = ceil_index(min_y - 0.5);
        let py1 = floor_index(max_y - 0.5);
        if px0 > px1 || py0 > py1 {
            return;
        }
        let inv = 1.0 / area;
        // barycentric weights as affine functions of the pixel centre
        let (a0, b0) = ((y1 - y2) * inv, (x2 - x1) * inv);
        let (a1, b1) = ((y2 - y0) * inv, (x0 - x2) * inv);
        let c0 = (x1 * y2 - x2 * y1) * inv;
        let c1 = (x2 * y0 - x0 * y2) * inv;
        let px1 = px1.min(self.w - 1);
        // depth as an affine function of the pixel centre:
        // z = l0 z0 + l1 z1 + l2 z2 = z2 + l0 (z0 - z2) + l1 (z1 - z2)
        let (dz0, dz1) = (z0 - z2, z1 - z2);
        let zx = a0 * dz0 + a1 * dz1;
        let zy = b0 * dz0 + b1 * dz1;
        let zc = z2 + c0 * dz0 + c1 * dz1;
        // l2 = 1 - l0 - l1, as an affine function of x on a row; the weights' zeros
        // on a row are at -r / a (a weight nearly constant along the row: none).
        // Only a triangle a few pixels wide or more looks for its span on each row.
        let a2 = -(a0 + a1);
        let spans = px1 - px0 >= 4;
        let inv_a = [a0, a1, a2].map(|a| if a.abs() > 1e-6 { 1.0 / a } else { 0.0 });
        for py in py0..=py1.min(self.h - 1) {
            let y = py as f32 + 0.5;
            let r0 = b0 * y + c0;
            let r1 = b1 * y + c1;
            let (mut sx0, mut sx1) = (px0, px1);
            if spans {
                // the pixels of this row whose centre can be inside: where each
                // weight a * x + r >= 0, widened by a pixel (the test below decides
                // every pixel exactly)
                let r2 = 1.0 - r0 - r1;
                let (mut lo, mut hi) = (px0 as f32 + 0.5, px1 as f32 + 0.5);
                for (ia, r) in [(inv_a[0], r0), (inv_a[1], r1), (inv_a[2], r2)] {
                    if ia > 0.0 {
                        lo = lo.max(-r * ia - 1.0);
                    } else if ia < 0.0 {
                        hi = hi.min(-r * ia + 1.0);
                    }
                }
                if lo.partial_cmp(&hi).is_none_or(|o| o.is_gt()) {
                    continue; // empty, or NaN
                }
                // lo >= px0 + 0.5 >= 0.5: truncation is floor
                sx0 = ((lo - 0.5) as usize).max(px0);
                sx1 = (floor_index(hi - 0.5) + 1).min(px1);
            }
            let zr = zc + zy * y;
            let row = py * self.w;
            for px in sx0..=sx1 {
                let x = px as f32 + 0.5;
                let l0 = a0 * x + r0;
                let l1 = a1 * x + r1;
                let l2 = 1.0 - l0 - l1;
                if l0 >= 0.0 && l1 >= 0.0 && l2 >= 0.0 {
                    let z = zr + zx * x;
                    let i = row + px;
                    if z < self.z[i] {
                        self.z[i] = z;
                        self.put(i, c);
                    }
                }
            }
        }
    }

    /// A line `width` pixels wide from `a` to `b` (screen points with depth), drawn
    /// `bias` nearer than it is; where the surface hides it, blended at `hidden`
    /// opacity (0: not at all). Lines do not write depth.
    pub fn line(&mut self, a: [f32; 3], b: [f32; 3], c: Rgb, width: usize, bias: f32, hidden: f32) {
        if self.z.len() != self.w * self.h {
            return; // a flat panel
        }
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.abs().max(dy.abs());
        if !len.is_finite() {
            return;
        }
        let steps = (len.ceil() as usize).clamp(1, 4 * (self.w + self.h));
        let r0 = (width as i64 - 1) / 2;
        let r1 = width as i64 / 2;
        for s in 0..=steps {
            let t = s as f32 / steps as f32;
            let x = a[0] + dx * t;
            let y = a[1] + dy * t;
            let z = a[2] + (b[2] - a[2]) * t - bias;
            let (cx, cy) = (floor_i64(x), floor_i64(y));
            for oy in -r0..=r1 {
                for ox in -r0..=r1 {
                    let (px, py) = (cx + ox, cy + oy);
                    if px < 0 || py < 0 || px >= self.w as i64 || py >= self.h as i64 {
                        continue;
                    }
                    let i = py as usize * self.w + px as usize;
                    if z <= self.z[i] {
                        self.put(i, c);
                    } else if hidden > 0.0 {
                        self.blend(i, c, hidden);
                    }
                }
            }
        }
    }

    /// Fills a rectangle (clipped).
    pub fn rect(&mut self, x: usize, y: usize, w: usize, h: usize, c: Rgb) {
        for py in y..(y + h).min(self.h) {
            for px in x..(x + w).min(self.w) {
                self.put(py * self.w + px, c);
            }
        }
    }

    /// Writes `text` with its top-left corner at `(x, y)`, each font pixel `scale`
    /// pixels wide (clipped).
    pub fn text(&mut self, x: usize, y: usize, text: &str, c: Rgb, scale: usize) {
        for (k, ch) in text.chars().enumerate() {
            let g = font::glyph(ch);
            let gx = x + k * font::ADVANCE * scale;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        self.rect(gx + col * scale, y + row * scale, scale, scale, c);
                    }
                }
            }
        }
    }

    /// Copies `other` into this panel with its top-left corner at `(x, y)` (clipped).
    pub fn blit(&mut self, other: &Panel, x: usize, y: usize) {
        for row in 0..other.h {
            let py = y + row;
            if py >= self.h || x >= self.w {
                break;
            }
            let n = other.w.min(self.w - x);
            let dst = 3 * (py * self.w + x);
            let src = 3 * row * other.w;
            self.rgb[dst..dst + 3 * n].copy_from_slice(&other.rgb[src..src + 3 * n]);
        }
    }

    /// The colour of a pixel.
    #[cfg(test)]
    pub fn at(&self, x: usize, y: usize) -> Rgb {
        let i = 3 * (y * self.w + x);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }
}

/// The smallest index `i >= 0` with `i as f32 >= v` (0 for NaN).
#[inline]
fn ceil_index(v: f32) -> usize {
    if v.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return 0; // at most 0, or NaN
    }
    let t = v as usize; // truncation (saturating)
    t + usize::from((t as f32) < v)
}

/// The largest index `i` with `i as f32 <= v`, 0 when there is none (or NaN).
#[inline]
fn floor_index(v: f32) -> usize {
    // for v >= 0 truncation is floor; below 0 it saturates to 0
    v as usize
}

/// `v.floor() as i64` without a call to libm's floorf (0 for NaN).
#[inline]
fn floor_i64(v: f32) -> i64 {
    let t = v as i64;
    t - i64::from((t as f32) > v)
}

#[cfg(test)]
mod tests {
    use super::*;

    const BG: Rgb = [0, 0, 0];

    #[test]
    fn a_triangle_covers_its_inside_and_the_nearer_one_wins() {
        let mut p = Panel::new(20, 20, BG);
        p.triangle(
            [[0.0, 0.0, 1.0], [20.0, 0.0, 1.0], [0.0, 20.0, 1.0]],
            [255, 0, 0],
        );
        assert_eq!(p.at(2, 2), [255, 0, 0]);
        assert_eq!(p.at(18, 18), BG, "outside the hypotenuse");
        // a farther one behind does not show, a nearer one does
        p.triangle(
            [[0.0, 0.0, 2.0], [10.0, 0.0, 2.0], [0.0, 10.0, 2.0]],
            [0, 255, 0],
        );
        assert_eq!(p.at(2, 2), [255, 0, 0]);
        p.triangle(
            [[0.0, 0.0, 0.5], [10.0, 0.0, 0.5], [0.0, 10.0, 0.5]],
            [0, 0, 255],
        );
        assert_eq!(p.at(2, 2), [0, 0, 255]);
        // either winding
        let mut q = Panel::new(20, 20, BG);
        q.triangle(
            [[0.0, 0.0, 1.0], [0.0, 20.0, 1.0], [20.0, 0.0, 1.0]],
            [9, 9, 9],
        );
        assert_eq!(q.at(2, 2), [9, 9, 9]);
    }

    #[test]
    fn two_triangles_sharing_an_edge_leave_no_gap() {
        let mut p = Panel::new(16, 16, BG);
        p.triangle(
            [[0.0, 0.0, 1.0], [16.0, 0.0, 1.0], [16.0, 16.0, 1.0]],
            [1, 1, 1],
        );
        p.triangle(
            [[0.0, 0.0, 1.0], [16.0, 16.0, 1.0], [0.0, 16.0, 1.0]],
            [1, 1, 1],
        );
        assert!(p.rgb.chunks(3).all(|c| c == [1, 1, 1]));
    }

    #[test]
    fn off_screen_and_degenerate_triangles_draw_nothing() {
        let mut p = Panel::new(8, 8, BG);
        p.triangle(
            [[-9.0, -9.0, 1.0], [-5.0, -9.0, 1.0], [-9.0, -5.0, 1.0]],
            [1, 2, 3],
        );
        p.triangle(
            [[1.0, 1.0, 1.0], [5.0, 5.0, 1.0], [3.0, 3.0, 1.0]],
            [1, 2, 3],
        );
        p.triangle(
            [[f32::NAN, 1.0, 1.0], [5.0, 5.0, 1.0], [3.0, 1.0, 1.0]],
            [1, 2, 3],
        );
        assert!(p.rgb.iter().all(|&b| b == 0));
    }

    #[test]
    fn a_hidden_line_is_faded_and_a_visible_one_is_not() {
        let mut p = Panel::new(20, 20, BG);
        p.triangle(
            [[0.0, 0.0, 1.0], [40.0, 0.0, 1.0], [0.0, 40.0, 1.0]],
            [100, 100, 100],
        );
        p.line([2.0, 5.5, 0.5], [18.0, 5.5, 0.5], [200, 0, 0], 1, 0.0, 0.5);
        assert_eq!(p.at(10, 5), [200, 0, 0]);
        p.line([2.0, 9.5, 3.0], [18.0, 9.5, 3.0], [200, 0, 0], 1, 0.0, 0.5);
        assert_eq!(p.at(5, 9), [150, 50, 50]);
    }

    #[test]
    fn a_flat_panel_takes_text_and_copies_but_no_triangles() {
        let mut p = Panel::flat(12, 12, BG);
        p.triangle(
            [[0.0, 0.0, 1.0], [12.0, 0.0, 1.0], [0.0, 12.0, 1.0]],
            [255, 0, 0],
        );
        p.line([0.0, 6.5, 0.0], [12.0, 6.5, 0.0], [255, 0, 0], 1, 0.0, 1.0);
        assert!(p.rgb.iter().all(|&b| b == 0));
        p.text(0, 0, "#1", [255, 255, 255], 1);
        assert!(p.rgb.contains(&255));
        assert_eq!(
            Panel::flat(3, 2, [1, 2, 3]).rgb,
            Panel::new(3, 2, [1, 2, 3]).rgb
        );
    }

    #[test]
    fn index_rounding_matches_ceil_and_floor() {
        for v in [0.0f32, 0.25, 0.5, 1.0, 1.5, 2.0, 7.999, 8.0, 1e6] {
            assert_eq!(ceil_index(v), v.ceil() as usize, "{v}");
            assert_eq!(floor_index(v), v.floor() as usize, "{v}");
        }
        assert_eq!((ceil_index(-0.5), floor_index(-0.5)), (0, 0));
        assert_eq!((ceil_index(f32::NAN), floor_index(f32::NAN)), (0, 0));
        for v in [-2.5f32, -1.0, -0.25, 0.0, 0.75, 3.0, 1e9, -1e9] {
            assert_eq!(floor_i64(v), v.floor() as i64, "{v}");
        }
        assert_eq!(floor_i64(f32::NAN), 0);
    }

    #[test]
    fn text_and_blit_stay_inside() {
        let mut p = Panel::new(30, 10, BG);
        p.text(0, 0, "#12", [255, 255, 255], 1);
        assert!(p.rgb.contains(&255));
        p.text(25, 5, "0000", [255, 255, 255], 2); // clipped, no panic
        let mut big = Panel::new(40, 40, [5, 5, 5]);
        big.blit(&p, 20, 35);
        assert_eq!(big.at(0, 0), [5, 5, 5]);
    }
}
