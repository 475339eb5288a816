//! Isosurfaces inside a volume rendering: one ray composites the transfer function's emission–absorption and the
//! exact surfaces of [`crate::isosurface`] in depth order (fog in front of a surface dims it, a translucent surface
//! dims the fog behind it), in one image.
//!
//! Issue "exact isosurfaces" names this as a plus; Knoll et al. (seed 002, `../shared/notes/knoll-isosurface.md`)
//! intersect surfaces exactly, and GigaVoxels [R08] §5 composites the volume front to back. Both are integrands of
//! the one traversal; this one takes whole brick segments ([`Integrand::TAKES_SPANS`]) like the surfaces, and walks
//! each cell once for both:
//!
//! - **The surfaces** are found exactly per trilinear cell, as without the volume ([`Isosurfaces::cell_with`]).
//! - **The volume** is sampled where the volume renderer samples it: each sample stands for one step around it and
//!   the next starts where the last one's step ended, the step being the one the volume renderer takes in that
//!   segment ([`BrickSpan::step`], rounded down to the ladder of [`StepLength`] so the pre-corrected tables apply).
//!   A sample's value is the trilinear interpolant of the cell it lies in (the same value the volume renderer
//!   takes from the brick), composited before the crossings that lie behind it. Constant nodes are integrated
//!   analytically, as the volume renderer does.
//! - **Culling** skips a brick or occupancy block only when neither the surfaces nor the transfer function can use
//!   its values; the samples in it are then passed over (they add nothing), at the positions and with the step
//!   they would have had, so culling changes no bit (tested). For that, a descent never stops at a coarse subtree
//!   to skip it whole ([`Integrand::CULLS_SUBTREES`]), as the volume renderer's does not.
//!
//! One difference from the volume renderer: samples come from the brick at the cone's level without blending it
//! with its parent (quadrilinear filtering), as the surfaces are; with no surface crossed the image is the volume
//! rendering's to within that filtering (tested).
//!
//! The GPU renderer's isosurface pipeline mirrors it (`RAY_FRAME_SURFACES_IN_VOLUME`); this is its reference.

use std::ops::ControlFlow;

use glam::{DVec3, Vec3};
use voxstream_core::VOXEL_MAX;

use crate::cell_intersection::cell_gradient;
use crate::cell_walk::{corners_at, walk_cells, CellVisit, CellVisitor};
use crate::emission_absorption::constant_emission;
use crate::integrand::{BrickSpan, Integrand, Sample};
use crate::isosurface::{Isosurfaces, SurfaceSettings};
use crate::lighting::{LightingSettings, RayLight};
use crate::settings::RenderSettings;
use crate::step_table::{StepLength, StepTable};
use crate::transfer_function::TransferLut;

/// What the volume part needs of a frame: the transfer function and how gradients scale.
#[derive(Clone, Copy, Debug)]
pub struct VolumeAroundSurfaces<'a> {
    lut: &'a TransferLut,
    gradient_scale: Vec3,
}

impl<'a> VolumeAroundSurfaces<'a> {
    /// The volume the frame's transfer function draws around its surfaces.
    pub fn new(lut: &'a TransferLut, settings: &RenderSettings) -> VolumeAroundSurfaces<'a> {
        VolumeAroundSurfaces { lut, gradient_scale: LightingSettings::new(settings).gradient_scale }
    }
}

/// The volume's samples along one ray: the step, and where the samples of the current segment fall.
struct VolumeSamples<'a> {
    volume: VolumeAroundSurfaces<'a>,
    step: Option<StepLength>,
    table: Option<&'a StepTable>,
    /// The distance up to which the volume is accounted for (the end of the last sample's step) when the current
    /// segment began, and after it ends.
    covered: f64,
    /// The current segment's first sample centre (`covered + ½·dt`), and the index of its next sample: sample `k`
    /// lies at `first + k·dt`, computed the same way whether the samples before it were taken or passed over.
    first: f64,
    next: u64,
}

impl VolumeSamples<'_> {
    /// Starts a segment that the volume renderer samples with steps of `desired` at most (the rung it would use:
    /// [`StepLength::keep_or_at_most`]).
    #[inline]
    fn begin(&mut self, desired: f64, from: f64) {
        let step = StepLength::keep_or_at_most(self.step, desired);
        if self.step != Some(step) {
            self.step = Some(step);
            self.table = Some(self.volume.lut.step_table(step));
        }
        if self.covered == f64::NEG_INFINITY {
            self.covered = from;
        }
        self.first = self.covered + 0.5 * step.world;
        self.next = 0;
    }

    /// Ends the segment at `to`: every sample whose centre lies before it is accounted for.
    #[inline]
    fn end(&mut self, to: f64) {
        let Some(step) = self.step else { return };
        self.pass_until(to);
        self.covered += self.next as f64 * step.world;
        self.next = 0;
    }

    /// Passes over the samples whose centres lie before `t` without taking them (they lie where nothing is
    /// visible: in blocks or bricks culled). The next sample is then the first at or after `t`, exactly as if
    /// they had been taken one by one.
    #[inline]
    fn pass_until(&mut self, t: f64) {
        let Some(step) = self.step else { return };
        let dt = step.world;
        if self.first + self.next as f64 * dt >= t {
            return;
        }
        let mut k = (((t - self.first) / dt).ceil().max(0.0) as u64).max(self.next);
        while k > self.next && self.first + (k - 1) as f64 * dt >= t {
            k -= 1;
        }
        while self.first + k as f64 * dt < t {
            k += 1;
        }
        self.next = k;
    }

    /// Takes the samples whose centres lie before the segment `span` (where the step shrank, the first one or two
    /// fall before its start: the volume renderer takes them from the segment's brick, and so does this).
    #[inline]
    fn take_before(&mut self, ray: &mut Isosurfaces<'_>, span: &BrickSpan<'_>) -> ControlFlow<()> {
        let (Some(step), Some(table)) = (self.step, self.table) else { return ControlFlow::Continue(()) };
        let dt = step.world;
        let light = ray.light().copied();
        loop {
            let centre = self.first + self.next as f64 * dt;
            if centre >= span.from {
                return ControlFlow::Continue(());
            }
            let (corners, p) = corners_at(span, std::array::from_fn(|a| span.origin[a] + centre * span.rate[a]));
            self.next += 1;
            self.composite(ray, table, light.as_ref(), &corners, p)?;
        }
    }

    /// Composites the sample of value `trilinear(corners, p)` (16-bit units) into `ray`.
    #[inline(always)]
    fn composite(
        &self,
        ray: &mut Isosurfaces<'_>,
        table: &StepTable,
        light: Option<&RayLight>,
        corners: &[f32; 8],
        p: [f32; 3],
    ) -> ControlFlow<()> {
        let entry = table.lookup(trilinear(corners, p) * (1.0 / VOXEL_MAX as f32));
        if entry.w <= 0.0 {
            return ControlFlow::Continue(());
        }
        let premultiplied = entry.truncate();
        let color = match light {
            Some(light) => {
                // Per voxel of the brick in normalised values, as the volume renderer's samples.
                let g = Vec3::from(cell_gradient(corners, p)) * (1.0 / VOXEL_MAX as f32);
                light.shade(premultiplied, entry.w, g * self.volume.gradient_scale)
            }
            None => premultiplied,
        };
        ray.absorb(color, entry.w)
    }

    /// Takes the samples of cell `c` whose centres lie before `limit`, compositing them into `ray`.
    #[inline(always)]
    fn take_until(&mut self, ray: &mut Isosurfaces<'_>, c: &CellVisit<'_>, limit: f64) -> ControlFlow<()> {
        let (Some(step), Some(table)) = (self.step, self.table) else { return ControlFlow::Continue(()) };
        // Samples before the cell lie in blocks the walk passed over.
        self.pass_until(c.t_in);
        let dt = step.world;
        let mut centre = self.first + self.next as f64 * dt;
        if centre >= limit {
            return ControlFlow::Continue(());
        }
        let light = ray.light().copied();
        while centre < limit {
            // From the sample's distance alone, so that its value does not depend on how the cell was reached.
            let p = c.at(centre);
            self.next += 1;
            centre = self.first + self.next as f64 * dt;
            self.composite(ray, table, light.as_ref(), &c.corners, p)?;
        }
        ControlFlow::Continue(())
    }
}

/// The trilinear interpolant of a cell's corners (x fastest) at cell-local `p`.
#[inline(always)]
fn trilinear(c: &[f32; 8], [x, y, z]: [f32; 3]) -> f32 {
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let front = lerp(lerp(c[0], c[1], x), lerp(c[2], c[3], x), y);
    let back = lerp(lerp(c[4], c[5], x), lerp(c[6], c[7], x), y);
    lerp(front, back, z)
}

/// Isosurfaces and the volume around them, composited along one ray.
pub struct SurfacesInVolume<'a> {
    surfaces: Isosurfaces<'a>,
    volume: VolumeSamples<'a>,
}

impl<'a> SurfacesInVolume<'a> {
    /// A ray that has met nothing; `volume_direction` is its direction in volume units per world unit.
    pub fn new(
        settings: &'a SurfaceSettings,
        volume: VolumeAroundSurfaces<'a>,
        volume_direction: DVec3,
    ) -> SurfacesInVolume<'a> {
        SurfacesInVolume {
            surfaces: Isosurfaces::new(settings, volume_direction),
            volume: VolumeSamples { volume, step: None, table: None, covered: f64::NEG_INFINITY, first: 0.0, next: 0 },
        }
    }

    /// The surfaces' part (first crossing, shadows) and the composited result.
    pub fn surfaces(&mut self) -> &mut Isosurfaces<'a> {
        &mut self.surfaces
    }

    /// Premultiplied `[r, g, b]` and opacity.
    pub fn result(&self) -> ([f32; 3], f32) {
        self.surfaces.result()
    }
}

impl CellVisitor for SurfacesInVolume<'_> {
    #[inline]
    fn block_can_contribute(&self, lower: u16, upper: u16) -> bool {
        let scale = 1.0 / VOXEL_MAX as f32;
        self.volume.volume.lut.is_visible_in(lower as f32 * scale, upper as f32 * scale)
            || self.surfaces.block_can_contribute(lower, upper)
    }

    #[inline(always)]
    fn visit(&mut self, cell: &CellVisit<'_>) -> ControlFlow<()> {
        let volume = &mut self.volume;
        self.surfaces.cell_with(cell, |ray, limit| volume.take_until(ray, cell, limit))
    }
}

impl Integrand for SurfacesInVolume<'_> {
    const TAKES_SPANS: bool = true;
    // The volume's samples are placed by each node's step, as the volume renderer's: no subtree is skipped whole.
    const CULLS_SUBTREES: bool = false;

    #[inline]
    fn can_contribute(&self, lower: f32, upper: f32) -> bool {
        self.volume.volume.lut.is_visible_in(lower, upper) || self.surfaces.can_contribute(lower, upper)
    }

    fn wants_gradient(&self) -> bool {
        false
    }

    fn set_step(&mut self, _step: StepLength) {}

    /// A lone sample (not used by the traversal for this integrand, which takes spans): a point of the surfaces'
    /// field.
    fn sample(&mut self, sample: Sample) -> ControlFlow<()> {
        self.surfaces.sample(sample)
    }

    fn constant(&mut self, from: f64, to: f64, value: f32) -> ControlFlow<()> {
        // A crossing at the node's entry first, then the volume over the distance not yet accounted for: from the
        // end of the last sample's step, which may lie a little before or after the node's entry (as the volume
        // renderer integrates it).
        self.surfaces.constant(from, to, value)?;
        let covered = self.volume.covered;
        let from = if covered == f64::NEG_INFINITY { from } else { covered };
        self.volume.covered = covered.max(to);
        match constant_emission(self.volume.volume.lut, value, to - from) {
            Some((color, alpha)) if from < to => self.surfaces.absorb(alpha * color, alpha),
            _ => ControlFlow::Continue(()),
        }
    }

    #[inline]
    fn skip_span(&mut self, from: f64, to: f64, step: f64) {
        // Nothing visible: the samples are passed over, positions and step kept as if they had been taken.
        self.volume.begin(step, from);
        self.volume.end(to);
    }

    #[inline(always)]
    fn span(&mut self, span: &BrickSpan<'_>, work: &mut u64) -> ControlFlow<()> {
        self.volume.begin(span.step, span.from);
        // Before the first cell's seam crossing at `from`.
        self.volume.take_before(&mut self.surfaces, span)?;
        let (flow, cells) = walk_cells(span, self);
        *work += cells;
        flow?;
        // Samples after the last cell visited lie in blocks passed over.
        self.volume.end(span.to);
        ControlFlow::Continue(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trilinear_is_exact_at_the_corners_and_linear_along_edges() {
        let c = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        for corner in 0..8 {
            let p = [(corner & 1) as f32, ((corner >> 1) & 1) as f32, (corner >> 2) as f32];
            assert_eq!(trilinear(&c, p), c[corner]);
        }
        assert_eq!(trilinear(&c, [0.5, 0.0, 0.0]), 0.5);
        assert_eq!(trilinear(&c, [0.5, 0.5, 0.5]), 3.5);
    }
}
