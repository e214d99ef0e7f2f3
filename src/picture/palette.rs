//! The picture's 256 colours: a pixel is one byte (an [`Ink`], an index into
//! [`palette`]) and the file an indexed PNG, a third of the bytes to draw, copy and
//! compress that RGB would be. The inks: the backgrounds and the text, the status
//! colours, the patches' edges, the outlines where the surface hides them (the status
//! colour faded towards a mid grey: no blending, the colour under a line is not
//! known in a palette) and one ramp of [`LEVELS`] shades per surface material (the
//! input's front and back, a patch in its hole's status).

use crate::report::HoleStatus;
use std::sync::LazyLock;

/// A palette index.
pub(crate) type Ink = u8;
/// An RGB colour.
pub(crate) type Rgb = [u8; 3];

pub(super) const FILLED_RGB: Rgb = [46, 204, 113];
pub(super) const SKIPPED_RGB: Rgb = [243, 176, 26];
pub(super) const FAILED_RGB: Rgb = [235, 64, 52];
const BG_RGB: Rgb = [30, 34, 40];
const BAND_RGB: Rgb = [18, 20, 24];
const TEXT_RGB: Rgb = [230, 230, 230];
const FRONT: [f32; 3] = [210.0, 208.0, 200.0];
const BACK: [f32; 3] = [95.0, 110.0, 150.0];
const PATCH: [f32; 3] = [70.0, 200.0, 120.0];
/// What a hidden outline is faded towards.
const GREY: [f32; 3] = [126.0, 125.0, 120.0];

pub(super) const BG: Ink = 0;
pub(super) const BAND: Ink = 1;
pub(super) const TEXT: Ink = 2;
const STATUS: Ink = 3; // filled, skipped, failed
const WIRE: Ink = 6; // per patch material
const HIDDEN: Ink = 10; // per status: strong, light
const RAMPS: usize = 16;
/// Shades per material, from unlit (0.28 of the colour) to lit.
pub(super) const LEVELS: usize = 40;

/// A surface's colour before shading.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Material {
    /// The input's surface seen from outside.
    Front,
    /// The input's surface seen from inside (through a hole).
    Back,
    /// A patch of a hole with this status.
    Patch(HoleStatus),
}

impl Material {
    /// A patch's, in its hole's status; else the input's front or back.
    #[inline]
    pub fn of(patch: Option<HoleStatus>, front: bool) -> Material {
        match patch {
            Some(s) => Material::Patch(s),
            None if front => Material::Front,
            None => Material::Back,
        }
    }

    fn index(self) -> usize {
        match self {
            Material::Front => 0,
            Material::Back => 1,
            Material::Patch(HoleStatus::Filled) => 2,
            Material::Patch(HoleStatus::Stitched) => 3,
            Material::Patch(HoleStatus::Skipped) => 4,
            Material::Patch(HoleStatus::Failed) => 5,
        }
    }

    fn base(self) -> [f32; 3] {
        match self {
            Material::Front => FRONT,
            Material::Back => BACK,
            Material::Patch(HoleStatus::Filled) => PATCH,
            // a patch of a hole not filled cannot be; shown in the status colour anyway
            Material::Patch(s) => super::status_color(s).map(f32::from),
        }
    }

    /// The shade of this material lit at `lit` (0 to 1: the cosine to the light).
    #[inline]
    pub fn shade(self, lit: f32) -> Ink {
        let level = (lit.clamp(0.0, 1.0) * (LEVELS - 1) as f32 + 0.5) as usize;
        (RAMPS + self.index() * LEVELS + level.min(LEVELS - 1)) as Ink
    }

    /// The colour of a patch's edges drawn over it.
    pub fn wire(self) -> Ink {
        WIRE + self.index().saturating_sub(2) as Ink
    }
}

fn status_index(s: HoleStatus) -> Ink {
    match s {
        HoleStatus::Filled | HoleStatus::Stitched => 0,
        HoleStatus::Skipped => 1,
        HoleStatus::Failed => 2,
    }
}

/// The ink of a status colour (outlines, labels).
pub(super) fn status_ink(s: HoleStatus) -> Ink {
    STATUS + status_index(s)
}

/// The ink of an outline where the surface hides it: `strong` (the overview) or
/// light (the close-ups).
pub(super) fn hidden_ink(s: HoleStatus, strong: bool) -> Ink {
    HIDDEN + 2 * status_index(s) + Ink::from(!strong)
}

/// The colours of the inks.
pub(crate) fn palette() -> &'static [Rgb; 256] {
    static PALETTE: LazyLock<[Rgb; 256]> = LazyLock::new(|| {
        let mut p = [[0u8; 3]; 256];
        let scale = |c: [f32; 3], k: f32| c.map(|x| (x * k).min(255.0) as u8);
        let mix = |c: Rgb, a: f32| {
            [0, 1, 2].map(|i| (GREY[i] + (c[i] as f32 - GREY[i]) * a).round() as u8)
        };
        p[BG as usize] = BG_RGB;
        p[BAND as usize] = BAND_RGB;
        p[TEXT as usize] = TEXT_RGB;
        let statuses = [HoleStatus::Filled, HoleStatus::Skipped, HoleStatus::Failed];
        for s in statuses {
            let c = super::status_color(s);
            p[status_ink(s) as usize] = c;
            p[hidden_ink(s, true) as usize] = mix(c, 0.45);
            p[hidden_ink(s, false) as usize] = mix(c, 0.35);
        }
        let materials = [
            Material::Front,
            Material::Back,
            Material::Patch(HoleStatus::Filled),
            Material::Patch(HoleStatus::Stitched),
            Material::Patch(HoleStatus::Skipped),
            Material::Patch(HoleStatus::Failed),
        ];
        for m in materials {
            if m.index() >= 2 {
                p[m.wire() as usize] = scale(m.base(), 0.45);
            }
            for level in 0..LEVELS {
                let k = 0.28 + 0.72 * level as f32 / (LEVELS - 1) as f32;
                p[RAMPS + m.index() * LEVELS + level] = scale(m.base(), k);
            }
        }
        p
    });
    &PALETTE
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_ink_has_its_own_place() {
        assert_eq!(RAMPS + 6 * LEVELS, 256, "the ramps fill the palette");
        assert!(WIRE + 4 <= HIDDEN && HIDDEN + 6 <= RAMPS as Ink);
        let p = palette();
        assert_eq!(p[status_ink(HoleStatus::Failed) as usize], FAILED_RGB);
        assert_eq!(p[status_ink(HoleStatus::Stitched) as usize], FILLED_RGB);
        // the ramps run from dark to the full colour
        let front = |lit| p[Material::Front.shade(lit) as usize];
        assert_eq!(front(1.0), [210, 208, 200]);
        assert!(front(0.0)[0] < 60 && front(0.5)[0] > front(0.0)[0]);
        assert_eq!(Material::Front.shade(f32::NAN), Material::Front.shade(0.0));
        let back = p[Material::Back.shade(1.0) as usize];
        assert!(back[2] > back[0], "back faces are bluish");
        // a hidden outline lies between its colour and the grey
        let h = p[hidden_ink(HoleStatus::Filled, true) as usize];
        assert!(h[1] > 125 && h[1] < 204);
    }
}
