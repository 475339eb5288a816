//! A validated particle set: positions, and per particle an optional smoothing length, mass and scalar attribute.
//!
//! Readers (`formats`) produce a [`RawParticles`]; [`ParticleSet::new`] checks it once (finite positions, positive
//! smoothing lengths and masses, matching lengths), so that the resampling loop of the particle producer never meets
//! a NaN.

use crate::error::GeometryError;

/// Particles as a file holds them, not yet validated. Optional columns are empty when the file has none, otherwise
/// as long as `positions`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RawParticles {
    /// Positions, file units.
    pub positions: Vec<[f64; 3]>,
    /// Smoothing length `h` (the kernel reaches `h`; file units), or per-atom radius for molecular formats.
    pub smoothing: Vec<f32>,
    /// Mass (density is mass per unit volume).
    pub masses: Vec<f32>,
    /// One scalar attribute, and its name.
    pub values: Vec<f32>,
    /// Name of the scalar attribute (`""` if none).
    pub value_name: String,
}

/// A particle set ready for resampling.
#[derive(Clone, Debug)]
pub struct ParticleSet {
    raw: RawParticles,
}

impl ParticleSet {
    /// Validates `raw`.
    pub fn new(raw: RawParticles) -> Result<ParticleSet, GeometryError> {
        if raw.positions.is_empty() {
            return Err(GeometryError::Invalid { message: "the file holds no particles".into() });
        }
        check_particles(&raw, 0)?;
        Ok(ParticleSet { raw })
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.raw.positions.len()
    }

    /// Never true (a set holds at least one particle).
    pub fn is_empty(&self) -> bool {
        self.raw.positions.is_empty()
    }

    /// Positions.
    pub fn positions(&self) -> &[[f64; 3]] {
        &self.raw.positions
    }

    /// Smoothing lengths (empty: none in the file).
    pub fn smoothing(&self) -> &[f32] {
        &self.raw.smoothing
    }

    /// Masses (empty: unit masses).
    pub fn masses(&self) -> &[f32] {
        &self.raw.masses
    }

    /// Scalar attribute (empty: none) and its name.
    pub fn values(&self) -> (&[f32], &str) {
        (&self.raw.values, &self.raw.value_name)
    }

    /// Axis-aligned bounds of the positions (lower, upper).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lower = [f64::INFINITY; 3];
        let mut upper = [f64::NEG_INFINITY; 3];
        for p in &self.raw.positions {
            for a in 0..3 {
                lower[a] = lower[a].min(p[a]);
                upper[a] = upper[a].max(p[a]);
            }
        }
        (lower, upper)
    }
}

/// Checks a run of particles whose first is particle `first` of its file (errors name the file's index): columns as
/// long as the positions, finite positions, positive and finite smoothing lengths and masses, finite values.
pub fn check_particles(raw: &RawParticles, first: u64) -> Result<(), GeometryError> {
    let count = raw.positions.len();
    for (name, column) in [("smoothing lengths", &raw.smoothing), ("masses", &raw.masses), ("values", &raw.values)] {
        if !column.is_empty() && column.len() != count {
            return Err(GeometryError::Invalid { message: format!("{} {name} for {count} particles", column.len()) });
        }
    }
    let index = |i: usize| first + i as u64;
    if let Some(i) = raw.positions.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(GeometryError::Invalid {
            message: format!(
                "particle {} has a non-finite position {:?}: fix or remove it",
                index(i),
                raw.positions[i]
            ),
        });
    }
    for (name, column) in [("smoothing length", &raw.smoothing), ("mass", &raw.masses)] {
        if let Some(i) = column.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(GeometryError::Invalid {
                message: format!("particle {} has {name} {}: it must be positive and finite", index(i), column[i]),
            });
        }
    }
    if let Some(i) = raw.values.iter().position(|v| !v.is_finite()) {
        return Err(GeometryError::Invalid {
            message: format!("particle {} has {} {}: values must be finite", index(i), raw.value_name, raw.values[i]),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_problem() {
        let raw = |positions: Vec<[f64; 3]>, smoothing: Vec<f32>| RawParticles {
            positions,
            smoothing,
            ..RawParticles::default()
        };
        assert!(ParticleSet::new(raw(vec![], vec![])).unwrap_err().to_string().contains("no particles"));
        let nan = ParticleSet::new(raw(vec![[0.0, f64::NAN, 1.0]], vec![])).unwrap_err().to_string();
        assert!(nan.contains("particle 0 has a non-finite position"), "{nan}");
        let h = ParticleSet::new(raw(vec![[0.0; 3]], vec![-1.0])).unwrap_err().to_string();
        assert!(h.contains("smoothing length -1"), "{h}");
        let lengths = ParticleSet::new(raw(vec![[0.0; 3]; 2], vec![1.0])).unwrap_err().to_string();
        assert!(lengths.contains("1 smoothing lengths for 2 particles"), "{lengths}");
        assert_eq!(ParticleSet::new(raw(vec![[1.0, 2.0, 3.0]], vec![0.5])).unwrap().len(), 1);
    }
}
