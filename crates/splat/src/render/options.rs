//! The renderer's settings ([`RenderOptions`]) and what a rendering did
//! ([`RenderStats`]).

use crate::SplatError;

/// Renderer settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Intensity of pixels of the valid region where no point is seen (the sky), in
    /// `[0, 1]`. Default 0.85: a bright, overcast sky.
    pub background: f32,
    /// Relative depth band of the anti-aliasing: samples within `(1 + depth_band)` of
    /// the nearest range of a pixel are averaged. Default 0.02.
    pub depth_band: f32,
    /// Level of detail: draw cells no denser than this many pixels between
    /// neighbouring points on the image (`None`: draw every point). Default `Some(0.65)`,
    /// about 2.4 samples per pixel where a cell is thinned (with the default splat
    /// size: closer to a pixel-integrated reference than 0.5 px with splats of 1.5,
    /// and its PGMs too, with 25 % fewer points; `docs/RESULTS.md`).
    pub lod_spacing_px: Option<f32>,
    /// Splat size factor over the nominal footprint (≥ 1 fills the gaps that the
    /// random jitter of a real sampling leaves). Default 1.25.
    pub splat_scale: f32,
    /// Largest splat half-width, pixels: splats are at most `2 r + 1` pixels wide
    /// (bounds the cost of points very close to the camera). Default 8.
    pub max_splat_radius_px: u32,
    /// Draw with rayon when the pool has more than one thread: each pass cut into as
    /// many runs as the pool has threads (at most 8), each run on buffers of its own
    /// (about 20 bytes a pixel of the valid pixels' box each, made with the renderer).
    /// The output is the same either way. Default true.
    pub parallel: bool,
    /// Fill isolated holes: a pixel of the valid region with no sample but at least 6
    /// of its 8 neighbours hit (at the valid region's edge: every valid neighbour, at
    /// least 3) takes their mean intensity and nearest range (the gaps a random
    /// subsample or a jittered sampling leaves). Default true.
    pub fill_holes: bool,
    /// Skip cells hidden behind what is already drawn (exact: the image is the same
    /// with or without it; only the time changes). Cameras with lens distortion are
    /// never culled this way. Default true.
    pub occlusion_culling: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            background: 0.85,
            depth_band: 0.02,
            lod_spacing_px: Some(0.65),
            splat_scale: 1.25,
            max_splat_radius_px: 8,
            parallel: true,
            fill_holes: true,
            occlusion_culling: true,
        }
    }
}

impl RenderOptions {
    pub(super) fn validate(&self) -> Result<(), SplatError> {
        let bad = |name, message: String| Err(SplatError::Parameter { name, message });
        if !(0.0..=1.0).contains(&self.background) {
            return bad(
                "background",
                format!("must be in [0, 1], got {}", self.background),
            );
        }
        if !(self.depth_band >= 0.0 && self.depth_band.is_finite()) {
            return bad(
                "depth_band",
                format!("must be >= 0, got {}", self.depth_band),
            );
        }
        if let Some(s) = self.lod_spacing_px
            && !(s > 0.0 && s.is_finite())
        {
            return bad("lod_spacing_px", format!("must be > 0, got {s}"));
        }
        if !(self.splat_scale > 0.0 && self.splat_scale.is_finite()) {
            return bad(
                "splat_scale",
                format!("must be > 0, got {}", self.splat_scale),
            );
        }
        Ok(())
    }
}

/// What one rendering did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// Cells drawn (in the field of view and not occluded).
    pub cells_drawn: usize,
    /// Cells in the field of view skipped as occluded (or as reaching no pixel of the
    /// valid pixels' box).
    pub cells_occluded: usize,
    /// Points drawn (after culling and level of detail).
    pub points_drawn: usize,
    /// Pixels with a rendered point.
    pub pixels_hit: usize,
}
