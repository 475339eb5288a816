//! The box a volume's spacing and origin place its samples in (sample `(i, j, k)` at `origin + spacing·(i, j, k)`),
//! checked once on open and on import, so that finite but extreme metadata is refused with the field that causes
//! it instead of surfacing later as a renderer's complaint about flags or a camera the user never gave (issue 41,
//! item 10: a store with spacing 1e308 passed `info`, then `render` said "invalid flags: volume placement must be
//! finite").
//!
//! The bounds: every coordinate of the box (and its size) within ±[`MAX_WORLD_COORDINATE`], so that it stays
//! finite in `f32` (the GPU's coordinates) and a camera framing it from a few box sizes away stays finite in
//! `f64` arithmetic; each spacing at least [`MIN_SPACING`], whose inverse `f32` holds; and the box's largest side at
//! least [`MIN_SIZE_PER_ORIGIN`] of the origin's largest coordinate, so that positions near the origin still tell
//! the box's far side from its near side (f64 keeps about 16 digits).

/// Largest magnitude of any coordinate of a volume's box, world units.
pub const MAX_WORLD_COORDINATE: f64 = 1e30;

/// Smallest spacing between samples, world units.
pub const MIN_SPACING: f64 = 1e-30;

/// Smallest largest side of a volume's box, as a fraction of its origin's largest coordinate.
pub const MIN_SIZE_PER_ORIGIN: f64 = 1e-8;

const AXES: [char; 3] = ['x', 'y', 'z'];

/// Checks the box of `dims` samples `spacing` apart from `origin` (both already finite, spacing positive); on a
/// problem returns the metadata field that causes it (`spacing` or `origin`) and what is wrong, with the fix.
pub fn check_world_extent(dims: [u64; 3], spacing: [f64; 3], origin: [f64; 3]) -> Result<(), (&'static str, String)> {
    const FIX: &str = "rescale the units (e.g. millimetres instead of metres) or shift the origin";
    if let Some(a) = (0..3).find(|&a| spacing[a] < MIN_SPACING) {
        return Err((
            "spacing",
            format!("{spacing:?} is below {MIN_SPACING:e} along {}, too fine for f32 coordinates: {FIX}", AXES[a]),
        ));
    }
    let size: [f64; 3] = std::array::from_fn(|a| spacing[a] * dims[a] as f64);
    if let Some(a) = (0..3).find(|&a| size[a] > MAX_WORLD_COORDINATE) {
        return Err((
            "spacing",
            format!(
                "{spacing:?} times {} samples spans {:e} along {}, beyond {MAX_WORLD_COORDINATE:e} (the box must \
                 stay finite in f32): {FIX}",
                dims[a], size[a], AXES[a]
            ),
        ));
    }
    if let Some(a) = (0..3).find(|&a| origin[a].abs() + size[a] > MAX_WORLD_COORDINATE) {
        return Err((
            "origin",
            format!(
                "{origin:?} puts the box at {:e} along {}, beyond ±{MAX_WORLD_COORDINATE:e} (the box must stay \
                 finite in f32): {FIX}",
                origin[a].abs() + size[a],
                AXES[a]
            ),
        ));
    }
    let largest_side = size.iter().copied().fold(0.0, f64::max);
    let farthest_origin = origin.iter().map(|o| o.abs()).fold(0.0, f64::max);
    if largest_side < MIN_SIZE_PER_ORIGIN * farthest_origin {
        return Err((
            "origin",
            format!(
                "{origin:?} is so far from 0 that a box {largest_side:e} wide (spacing {spacing:?}) cannot be placed \
                 precisely there (f64 keeps about 16 digits): {FIX}"
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(dims: [u64; 3], spacing: [f64; 3], origin: [f64; 3]) -> Option<&'static str> {
        check_world_extent(dims, spacing, origin).err().map(|(field, _)| field)
    }

    #[test]
    fn ordinary_boxes_pass() {
        assert_eq!(field([512, 512, 300], [0.5, 0.5, 1.25], [-128.0, -128.0, 0.0]), None);
        // Microscopy in metres, and a galaxy in metres.
        assert_eq!(field([2048, 2048, 100], [1e-7, 1e-7, 2e-7], [0.0; 3]), None);
        assert_eq!(field([1024; 3], [1e19; 3], [-5e21; 3]), None);
        // A small volume at map coordinates (UTM, metres).
        assert_eq!(field([100; 3], [0.01; 3], [500000.0, 5000000.0, 300.0]), None);
    }

    #[test]
    fn the_field_at_fault_is_named() {
        assert_eq!(field([64; 3], [1e308, 1.0, 1.0], [0.0; 3]), Some("spacing"));
        assert_eq!(field([64; 3], [1e29, 1.0, 1.0], [0.0; 3]), Some("spacing"));
        assert_eq!(field([64; 3], [1e-40, 1.0, 1.0], [0.0; 3]), Some("spacing"));
        assert_eq!(field([64; 3], [1.0; 3], [0.0, 1e308, 0.0]), Some("origin"));
        assert_eq!(field([64; 3], [1.0; 3], [0.0, 0.0, -1e30]), Some("origin"));
        assert_eq!(field([64; 3], [1e-6; 3], [1e6, 0.0, 0.0]), Some("origin"));
        let (_, message) = check_world_extent([64; 3], [1e308, 1.0, 1.0], [0.0; 3]).unwrap_err();
        assert!(message.contains("along x") && message.contains("rescale the units"), "{message}");
    }
}
