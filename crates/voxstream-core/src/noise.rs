//! Aperiodic value noise and band-limited fBm, in `f64`, for hypertextures: the procedural scenes' and the amplified
//! meshes' (`voxstream-procedural`, `voxstream-geometry`), so it lives below both, beside the `Producer` trait.
//!
//! Lattice values come from a 64-bit integer hash, so the noise never repeats however deep the zoom (a 256-entry
//! permutation table, as in classic Perlin noise, would tile at the finest octaves of a 2¹⁷³ volume). Value noise with
//! a quintic fade is bounded by 1 exactly, which the hypertexture oracle relies on.

/// Hash of a lattice point to `[-1, 1]`.
#[inline]
fn lattice(x: i64, y: i64, z: i64, seed: u64) -> f64 {
    let mut h = seed ^ 0x9E37_79B9_7F4A_7C15;
    for v in [x as u64, y as u64, z as u64] {
        h ^= v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 31)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 29;
    }
    (h >> 11) as f64 * (2.0 / (1u64 << 53) as f64) - 1.0
}

#[inline]
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Value noise at `p` (lattice spacing 1), in `[-1, 1]`.
pub fn value_noise(p: [f64; 3], seed: u64) -> f64 {
    let cell = p.map(|v| v.floor());
    let f = [fade(p[0] - cell[0]), fade(p[1] - cell[1]), fade(p[2] - cell[2])];
    let c = cell.map(|v| v as i64);
    let mut result = 0.0;
    for corner in 0..8 {
        let (dx, dy, dz) = ((corner & 1) as i64, ((corner >> 1) & 1) as i64, (corner >> 2) as i64);
        let w = (if dx == 1 { f[0] } else { 1.0 - f[0] })
            * (if dy == 1 { f[1] } else { 1.0 - f[1] })
            * (if dz == 1 { f[2] } else { 1.0 - f[2] });
        result += w * lattice(c[0] + dx, c[1] + dy, c[2] + dz, seed);
    }
    result
}

/// Fractal Brownian motion: `Σ gainᵒ · noise(p · base · 2ᵒ)` over `octaves`, where octaves shorter than
/// `min_wavelength` are dropped (and the last kept one fades out), so a coarse level gets a band-limited field: the mip
/// of the fine one, not its aliased point samples. Bounded by [`fbm_bound`].
pub fn fbm(p: [f64; 3], base_frequency: f64, octaves: u32, gain: f64, min_wavelength: f64, seed: u64) -> f64 {
    let mut sum = 0.0;
    let mut amplitude = 1.0;
    let mut frequency = base_frequency;
    for octave in 0..octaves {
        let wavelength = 1.0 / frequency;
        // Full weight above two minimum wavelengths, fading to zero at one.
        let weight = ((wavelength / min_wavelength) - 1.0).clamp(0.0, 1.0);
        if weight == 0.0 {
            break;
        }
        sum += weight * amplitude * value_noise(p.map(|v| v * frequency), seed.wrapping_add(octave as u64));
        amplitude *= gain;
        frequency *= 2.0;
    }
    sum
}

/// Upper bound of `|fbm|` for `octaves` and `gain`.
pub fn fbm_bound(octaves: u32, gain: f64) -> f64 {
    (0..octaves).map(|o| gain.powi(o as i32)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_and_continuous() {
        let mut previous = value_noise([0.0, 0.3, 0.7], 1);
        for i in 1..2000 {
            let x = i as f64 * 0.001;
            let v = value_noise([x, 0.3, 0.7], 1);
            assert!((-1.0..=1.0).contains(&v));
            assert!((v - previous).abs() < 0.01, "jump at {x}");
            previous = v;
        }
    }

    #[test]
    fn lattice_values_are_reproduced() {
        assert_eq!(value_noise([3.0, 4.0, 5.0], 7), lattice(3, 4, 5, 7));
        assert_ne!(lattice(3, 4, 5, 7), lattice(3, 4, 6, 7));
    }

    #[test]
    fn fbm_drops_octaves_below_the_wavelength() {
        let p = [0.123, 0.456, 0.789];
        let coarse = fbm(p, 4.0, 16, 0.5, 0.125, 3);
        let only_first = value_noise(p.map(|v| v * 4.0), 3);
        assert!((coarse - only_first).abs() < 1e-12, "only the first octave is at least two minimum wavelengths long");
        assert!(fbm(p, 4.0, 16, 0.5, 1e-9, 3).abs() <= fbm_bound(16, 0.5));
    }
}
