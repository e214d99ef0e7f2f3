//! The rasteriser: a panel of RGB pixels with a depth buffer, filled triangles with
//! a depth test, thick lines that show through the surface faded where it hides them,
//! rectangles and text. Pixel centres are at `(x + 0.5, y + 0.5)`; depth grows away
//! from the viewer.

use super::font;
use super::palette::Ink;

/// A rectangle of pixels (palette inks) with its depth buffer.
#[derive(Clone)]
pub(crate) struct Panel {
    pub w: usize,
    pub h: usize,
    pub px: Vec<Ink>,
    z: Vec<f32>,
}

impl Panel {
    /// A panel filled with `bg`, every depth at infinity.
    pub fn new(w: usize, h: usize, bg: Ink) -> Panel {
        Panel {
            w,
            h,
            px: vec![bg; w * h],
            z: vec![f32::INFINITY; w * h],
        }
    }

    /// A panel filled with `bg` without a depth buffer, for rectangles, text and
    /// copies only: a triangle or line drawn on it draws nothing.
    pub fn flat(w: usize, h: usize, bg: Ink) -> Panel {
        Panel {
            w,
            h,
            px: vec![bg; w * h],
            z: Vec::new(),
        }
    }

    /// Fills a triangle of screen points `(x, y, depth)` with one ink where it is
    /// nearer than what is drawn; `ink()` is called when it first draws a pixel (a
    /// face hidden, or between pixel centres, is not shaded). A pixel is inside when
    /// its centre is (every barycentric weight at least 0); on a row, the first and
    /// the last pixel inside are found by that test and the pixels between them taken
    /// as inside (a triangle is convex), so that a wide triangle costs a depth test
    /// per pixel.
    pub fn triangle(&mut self, v: [[f32; 3]; 3], ink: impl Fn() -> Ink) {
        if self.z.len() != self.w * self.h {
            return; // a flat panel
        }
        let [[x0, y0, _], [x1, y1, _], [x2, y2, _]] = v;
        // most faces: corners near the panel (false for NaN), small bounds
        let near = |t: f32| t.abs() < FIXED_MAX;
        if near(x0)
            && near(y0)
            && near(x1)
            && near(y1)
            && near(x2)
            && near(y2)
            && self.small_triangle(v, &ink)
        {
            return;
        }
        let (w, h) = (self.w as f32, self.h as f32);
        // plain comparisons (a NaN corner is caught by the area test below)
        let min = |a: f32, b: f32| if a < b { a } else { b };
        let max = |a: f32, b: f32| if a > b { a } else { b };
        let min_x = max(min(min(x0, x1), x2), 0.0);
        let max_x = min(max(max(x0, x1), x2), w - 0.5);
        let min_y = max(min(min(y0, y1), y2), 0.0);
        let max_y = min(max(max(y0, y1), y2), h - 0.5);
        if !(min_x <= max_x && min_y <= max_y) {
            return;
        }
        // pixels whose centre may be inside (most faces of an overview have none)
        let px0 = ceil_index(min_x - 0.5);
        let px1 = floor_index(max_x - 0.5).min(self.w - 1);
        let py0 = ceil_index(min_y - 0.5);
        let py1 = floor_index(max_y - 0.5).min(self.h - 1);
        if px0 > px1 || py0 > py1 {
            return;
        }
        let area = twice_area(v);
        if !area.is_finite() || area.abs() <= 1e-12 {
            return; // edge-on, or not finite
        }
        let p = Plane::new(v, area);
        let (a0, b0, a1, b1, c0, c1) = (p.a0, p.b0, p.a1, p.b1, p.c0, p.c1);
        let (zx, zy, zc) = (p.zx, p.zy, p.zc);
        // l2 = 1 - l0 - l1, as an affine function of x on a row; the weights' zeros
        // on a row are at -r / a (a weight nearly constant along the row: none).
        // Only a triangle a few pixels wide or more looks for its span on each row.
        let a2 = -(a0 + a1);
        let spans = px1 - px0 >= 4;
        let inv_a = if spans {
            [a0, a1, a2].map(|a| if a.abs() > 1e-6 { 1.0 / a } else { 0.0 })
        } else {
            [0.0; 3]
        };
        let inside = |px: usize, r0: f32, r1: f32| {
            let x = px as f32 + 0.5;
            let l0 = a0 * x + r0;
            let l1 = a1 * x + r1;
            l0 >= 0.0 && l1 >= 0.0 && 1.0 - l0 - l1 >= 0.0
        };
        let mut c = None;
        for py in py0..=py1 {
            let y = py as f32 + 0.5;
            let r0 = b0 * y + c0;
            let r1 = b1 * y + c1;
            let (mut sx0, mut sx1) = (px0, px1);
            if spans {
                // the pixels of this row whose centre can be inside: where each
                // weight a * x + r >= 0, widened by a pixel (the test decides the
                // span's ends exactly)
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
            while sx0 <= sx1 && !inside(sx0, r0, r1) {
                sx0 += 1;
            }
            if sx0 > sx1 {
                continue;
            }
            while sx1 > sx0 && !inside(sx1, r0, r1) {
                sx1 -= 1;
            }
            let zr = zc + zy * y;
            let row = py * self.w;
            let zs = &mut self.z[row + sx0..=row + sx1];
            let ps = &mut self.px[row + sx0..=row + sx1];
            for (k, (zd, pd)) in zs.iter_mut().zip(ps.iter_mut()).enumerate() {
                let z = zr + zx * ((sx0 + k) as f32 + 0.5);
                if z < *zd {
                    *zd = z;
                    *pd = *c.get_or_insert_with(&ink);
                }
            }
        }
    }

    /// [`Panel::triangle`] of a triangle with its corners within [`FIXED_MAX`] of the
    /// panel's origin, when the pixels of its bounds are fewer than [`SMALL`] each way
    /// (most faces of a picture; `false`, nothing drawn, otherwise). The corners in
    /// fixed point (1/256 pixel, rounded), the bounds and the edge functions in
    /// integers, stepped from pixel to pixel, exactly (a pixel centre on an edge is
    /// inside); the depth is the plane's, as in the general case, from the pixel
    /// centre's coordinates (exact in f32).
    fn small_triangle(&mut self, v: [[f32; 3]; 3], ink: &impl Fn() -> Ink) -> bool {
        // t * SUB rounded to an integer without a conversion's range checks: below
        // 2^22, the sum with 1.5 * 2^23 holds it in its low mantissa bits
        const MAGIC: f32 = 12_582_912.0;
        const MAGIC_BITS: i64 = 0x4B40_0000;
        let fixed = |t: f32| i64::from((t * SUB as f32 + MAGIC).to_bits()) - MAGIC_BITS;
        let [[x0, y0, _], [x1, y1, _], [x2, y2, _]] = v;
        let (fx, fy) = ([x0, x1, x2].map(fixed), [y0, y1, y2].map(fixed));
        // the pixels whose centre (p * SUB + SUB / 2) is within the bounds
        let first = |lo: i64| (lo - SUB / 2 + SUB - 1).div_euclid(SUB).max(0);
        let last = |hi: i64, n: usize| (hi - SUB / 2).div_euclid(SUB).min(n as i64 - 1);
        let min3 = |a: [i64; 3]| a[0].min(a[1]).min(a[2]);
        let max3 = |a: [i64; 3]| a[0].max(a[1]).max(a[2]);
        let (px0, px1) = (first(min3(fx)), last(max3(fx), self.w));
        let (py0, py1) = (first(min3(fy)), last(max3(fy), self.h));
        if px0 > px1 || py0 > py1 {
            return true; // no pixel centre inside
        }
        if px1 - px0 >= SMALL as i64 || py1 - py0 >= SMALL as i64 {
            return false;
        }
        let (px0, px1, py0, py1) = (px0 as usize, px1 as usize, py0 as usize, py1 as usize);
        let orient = (fx[1] - fx[0]) * (fy[2] - fy[0]) - (fx[2] - fx[0]) * (fy[1] - fy[0]);
        let area = twice_area(v);
        if orient == 0 || !area.is_finite() || area.abs() <= 1e-12 {
            return true; // degenerate (once snapped, or as given)
        }
        // the edge function of edge a -> b at p, times the orientation's sign: at
        // least 0 on the inner side; its steps per pixel in x and y
        let sign = orient.signum();
        let (cx, cy) = ((px0 as i64) * SUB + SUB / 2, (py0 as i64) * SUB + SUB / 2);
        let edge = |a: usize, b: usize| {
            let (ex, ey) = (fx[b] - fx[a], fy[b] - fy[a]);
            let at = sign * (ex * (cy - fy[a]) - ey * (cx - fx[a]));
            (at, -sign * ey * SUB, sign * ex * SUB)
        };
        let (e0, sx0, sy0) = edge(1, 2);
        let (e1, sx1, sy1) = edge(2, 0);
        let (e2, sx2, sy2) = edge(0, 1);
        // depth, affine in the pixel centre (in f32, from the unsnapped corners)
        let Plane { zx, zy, zc, .. } = Plane::new(v, area);
        let (mut r0, mut r1, mut r2) = (e0, e1, e2);
        let mut c = None;
        let (w, n) = (self.w, px1 - px0 + 1);
        // the bounds' rows, each from its first pixel (the last one n pixels long)
        let span = py0 * w + px0..py1 * w + px1 + 1;
        let (zs, ps) = (&mut self.z[span.clone()], &mut self.px[span]);
        // the pixel centres' coordinates: exact in f32 (integers and a half)
        let (mut y, x0) = (py0 as f32 + 0.5, px0 as f32 + 0.5);
        let mut row = 0;
        while row < zs.len() {
            let zr = zc + zy * y;
            let (mut w0, mut w1, mut w2) = (r0, r1, r2);
            for k in row..row + n {
                if (w0 | w1 | w2) >= 0 {
                    let z = zr + zx * ((k - row) as u32 as f32 + x0);
                    if z < zs[k] {
                        zs[k] = z;
                        ps[k] = *c.get_or_insert_with(ink);
                    }
                }
                w0 += sx0;
                w1 += sx1;
                w2 += sx2;
            }
            r0 += sy0;
            r1 += sy1;
            r2 += sy2;
            y += 1.0;
            row += w;
        }
        true
    }

    /// A line `width` pixels wide (across its main direction) from `a` to `b`
    /// (screen points with depth), drawn `bias` nearer than it is; where the surface
    /// hides it, drawn in `hidden` (`None`: not at all). Lines do not write depth.
    pub fn line(
        &mut self,
        a: [f32; 3],
        b: [f32; 3],
        c: Ink,
        width: usize,
        bias: f32,
        hidden: Option<Ink>,
    ) {
        if self.z.len() != self.w * self.h {
            return; // a flat panel
        }
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.abs().max(dy.abs());
        if !len.is_finite() {
            return;
        }
        let steep = dy.abs() > dx.abs();
        let steps = (len.ceil() as usize).clamp(1, 4 * (self.w + self.h));
        let r0 = (width as i64 - 1) / 2;
        let r1 = width as i64 / 2;
        let (w, h) = (self.w as i64, self.h as i64);
        for s in 0..=steps {
            let t = s as f32 / steps as f32;
            let x = a[0] + dx * t;
            let y = a[1] + dy * t;
            let z = a[2] + (b[2] - a[2]) * t - bias;
            let (cx, cy) = (floor_i64(x), floor_i64(y));
            for o in -r0..=r1 {
                let (px, py) = if steep { (cx + o, cy) } else { (cx, cy + o) };
                if px < 0 || py < 0 || px >= w || py >= h {
                    continue;
                }
                let i = py as usize * self.w + px as usize;
                if z <= self.z[i] {
                    self.px[i] = c;
                } else if let Some(hc) = hidden {
                    self.px[i] = hc;
                }
            }
        }
    }

    /// Fills a rectangle (clipped).
    pub fn rect(&mut self, x: usize, y: usize, w: usize, h: usize, c: Ink) {
        if x >= self.w {
            return;
        }
        let x1 = (x + w).min(self.w);
        for py in y..(y + h).min(self.h) {
            self.px[py * self.w + x..py * self.w + x1].fill(c);
        }
    }

    /// Writes `text` with its top-left corner at `(x, y)`, each font pixel `scale`
    /// pixels wide (clipped).
    pub fn text(&mut self, x: usize, y: usize, text: &str, c: Ink, scale: usize) {
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
            let dst = py * self.w + x;
            let src = row * other.w;
            self.px[dst..dst + n].copy_from_slice(&other.px[src..src + n]);
        }
    }

    /// The ink of a pixel.
    #[cfg(test)]
    pub fn at(&self, x: usize, y: usize) -> Ink {
        self.px[y * self.w + x]
    }
}

/// Twice the signed area of the screen triangle `v` (its depths aside).
#[inline]
fn twice_area([[x0, y0, _], [x1, y1, _], [x2, y2, _]]: [[f32; 3]; 3]) -> f32 {
    (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
}

/// The barycentric weights `l0`, `l1` of a triangle's corners 0 and 1 and its depth,
/// as affine functions of the pixel centre `(x, y)`: `l0 = a0 x + b0 y + c0`, the
/// same for `l1`, `z = zx x + zy y + zc`.
struct Plane {
    a0: f32,
    b0: f32,
    a1: f32,
    b1: f32,
    c0: f32,
    c1: f32,
    zx: f32,
    zy: f32,
    zc: f32,
}

impl Plane {
    /// The plane of the triangle `v` of twice the signed area `area` (not 0).
    #[inline]
    fn new(v: [[f32; 3]; 3], area: f32) -> Plane {
        let [[x0, y0, z0], [x1, y1, z1], [x2, y2, z2]] = v;
        let inv = 1.0 / area;
        let (a0, b0) = ((y1 - y2) * inv, (x2 - x1) * inv);
        let (a1, b1) = ((y2 - y0) * inv, (x0 - x2) * inv);
        let c0 = (x1 * y2 - x2 * y1) * inv;
        let c1 = (x2 * y0 - x0 * y2) * inv;
        // z = l0 z0 + l1 z1 + l2 z2 = z2 + l0 (z0 - z2) + l1 (z1 - z2)
        let (dz0, dz1) = (z0 - z2, z1 - z2);
        Plane {
            a0,
            b0,
            a1,
            b1,
            c0,
            c1,
            zx: a0 * dz0 + a1 * dz1,
            zy: b0 * dz0 + b1 * dz1,
            zc: z2 + c0 * dz0 + c1 * dz1,
        }
    }
}

/// Triangles whose pixel bounds are under this many pixels each way are drawn in
/// fixed point ([`Panel::small_triangle`]), larger ones row by row in f32.
const SMALL: usize = 16;
/// Sub-pixel steps of the fixed point.
const SUB: i64 = 256;
/// Corners farther than this from the panel's origin (pixels) take the general path
/// (a corner times [`SUB`] stays below 2^22, as the rounding in
/// [`Panel::small_triangle`] needs; the products of the edge functions, below 2^46,
/// far inside i64).
const FIXED_MAX: f32 = 8192.0;

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

    const BG: Ink = 0;

    #[test]
    fn a_triangle_covers_its_inside_and_the_nearer_one_wins() {
        let mut p = Panel::new(20, 20, BG);
        p.triangle([[0.0, 0.0, 1.0], [20.0, 0.0, 1.0], [0.0, 20.0, 1.0]], || 7);
        assert_eq!(p.at(2, 2), 7);
        assert_eq!(p.at(18, 18), BG, "outside the hypotenuse");
        // a farther one behind does not show, a nearer one does
        p.triangle([[0.0, 0.0, 2.0], [10.0, 0.0, 2.0], [0.0, 10.0, 2.0]], || 8);
        assert_eq!(p.at(2, 2), 7);
        p.triangle([[0.0, 0.0, 0.5], [10.0, 0.0, 0.5], [0.0, 10.0, 0.5]], || 9);
        assert_eq!(p.at(2, 2), 9);
        // either winding
        let mut q = Panel::new(20, 20, BG);
        q.triangle([[0.0, 0.0, 1.0], [0.0, 20.0, 1.0], [20.0, 0.0, 1.0]], || 9);
        assert_eq!(q.at(2, 2), 9);
    }

    #[test]
    fn two_triangles_sharing_an_edge_leave_no_gap() {
        let mut p = Panel::new(16, 16, BG);
        p.triangle([[0.0, 0.0, 1.0], [16.0, 0.0, 1.0], [16.0, 16.0, 1.0]], || 1);
        p.triangle([[0.0, 0.0, 1.0], [16.0, 16.0, 1.0], [0.0, 16.0, 1.0]], || 1);
        assert!(p.px.iter().all(|&c| c == 1));
    }

    #[test]
    fn a_triangle_fills_exactly_the_pixels_whose_centre_is_inside() {
        // the row spans against the test on every pixel, on random triangles
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..300 {
            let v: [[f32; 3]; 3] = std::array::from_fn(|_| {
                [
                    rng.random_range(-8.0..40.0),
                    rng.random_range(-8.0..40.0),
                    1.0,
                ]
            });
            let mut p = Panel::new(32, 32, BG);
            p.triangle(v, || 1);
            let [[x0, y0, _], [x1, y1, _], [x2, y2, _]] = v;
            let area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
            if area.abs() < 1e-3 {
                continue;
            }
            let edge = |ax: f32, ay: f32, bx: f32, by: f32, x: f32, y: f32| {
                ((bx - ax) * (y - ay) - (by - ay) * (x - ax)) / area
            };
            for py in 0..32 {
                for px in 0..32 {
                    let (x, y) = (px as f32 + 0.5, py as f32 + 0.5);
                    let l = [
                        edge(x1, y1, x2, y2, x, y),
                        edge(x2, y2, x0, y0, x, y),
                        edge(x0, y0, x1, y1, x, y),
                    ];
                    // clearly inside or clearly outside (rounding aside)
                    if l.iter().all(|&w| w > 1e-4) {
                        assert_eq!(p.at(px, py), 1, "{v:?} at {px},{py}");
                    } else if l.iter().any(|&w| w < -1e-4) {
                        assert_eq!(p.at(px, py), BG, "{v:?} at {px},{py}");
                    }
                }
            }
        }
    }

    #[test]
    fn off_screen_and_degenerate_triangles_draw_nothing() {
        let mut p = Panel::new(8, 8, BG);
        p.triangle(
            [[-9.0, -9.0, 1.0], [-5.0, -9.0, 1.0], [-9.0, -5.0, 1.0]],
            || 3,
        );
        p.triangle([[1.0, 1.0, 1.0], [5.0, 5.0, 1.0], [3.0, 3.0, 1.0]], || 3);
        p.triangle(
            [[f32::NAN, 1.0, 1.0], [5.0, 5.0, 1.0], [3.0, 1.0, 1.0]],
            || 3,
        );
        assert!(p.px.iter().all(|&b| b == 0));
    }

    #[test]
    fn a_hidden_line_is_faded_and_a_visible_one_is_not() {
        let mut p = Panel::new(20, 20, BG);
        p.triangle(
            [[0.0, 0.0, 1.0], [40.0, 0.0, 1.0], [0.0, 40.0, 1.0]],
            || 100,
        );
        p.line([2.0, 5.5, 0.5], [18.0, 5.5, 0.5], 200, 1, 0.0, Some(150));
        assert_eq!(p.at(10, 5), 200);
        p.line([2.0, 9.5, 3.0], [18.0, 9.5, 3.0], 200, 1, 0.0, Some(150));
        assert_eq!(p.at(5, 9), 150);
        p.line([2.0, 12.5, 3.0], [18.0, 12.5, 3.0], 200, 1, 0.0, None);
        assert_eq!(p.at(5, 12), 100, "hidden and not shown");
        // three pixels wide across a flat line, one pixel along it past its ends
        p.line([2.0, 15.5, 0.5], [18.0, 15.5, 0.5], 42, 3, 0.0, None);
        let col: Vec<Ink> = (13..18).map(|y| p.at(10, y)).collect();
        assert_eq!(col, [100, 42, 42, 42, 100]);
    }

    #[test]
    fn a_flat_panel_takes_text_and_copies_but_no_triangles() {
        let mut p = Panel::flat(12, 12, BG);
        p.triangle([[0.0, 0.0, 1.0], [12.0, 0.0, 1.0], [0.0, 12.0, 1.0]], || 7);
        p.line([0.0, 6.5, 0.0], [12.0, 6.5, 0.0], 7, 1, 0.0, Some(7));
        assert!(p.px.iter().all(|&b| b == 0));
        p.text(0, 0, "#1", 255, 1);
        assert!(p.px.contains(&255));
        assert_eq!(Panel::flat(3, 2, 3).px, Panel::new(3, 2, 3).px);
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
        p.text(0, 0, "#12", 255, 1);
        assert!(p.px.contains(&255));
        p.text(25, 5, "0000", 255, 2); // clipped, no panic
        let mut big = Panel::new(40, 40, 5);
        big.blit(&p, 20, 35);
        assert_eq!(big.at(0, 0), 5);
    }
}
