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
        let mut rgb = Vec::with_capacity(w * h * 3);
        for _ in 0..w * h {
            rgb.extend_from_slice(&bg);
        }
        Panel {
            w,
            h,
            rgb,
            z: vec![f32::INFINITY; w * h],
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
        let px0 = (min_x - 0.5).ceil().max(0.0) as usize;
        let px1 = (max_x - 0.5).floor() as usize;
        let py0 = (min_y - 0.5).ceil().max(0.0) as usize;
        let py1 = (max_y - 0.5).floor() as usize;
        if px0 > px1 || py0 > py1 {
            return;
        }
        let inv = 1.0 / area;
        // barycentric weights as affine functions of the pixel centre
        let (a0, b0) = ((y1 - y2) * inv, (x2 - x1) * inv);
        let (a1, b1) = ((y2 - y0) * inv, (x0 - x2) * inv);
        let c0 = (x1 * y2 - x2 * y1) * inv;
        let c1 = (x2 * y0 - x0 * y2) * inv;
        for py in py0..=py1.min(self.h - 1) {
            let y = py as f32 + 0.5;
            let row = py * self.w;
            for px in px0..=px1.min(self.w - 1) {
                let x = px as f32 + 0.5;
                let l0 = a0 * x + b0 * y + c0;
                let l1 = a1 * x + b1 * y + c1;
                let l2 = 1.0 - l0 - l1;
                if l0 >= 0.0 && l1 >= 0.0 && l2 >= 0.0 {
                    let z = l0 * z0 + l1 * z1 + l2 * z2;
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
            let (cx, cy) = (x.floor() as i64, y.floor() as i64);
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
