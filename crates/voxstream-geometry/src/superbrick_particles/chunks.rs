//! Where the out-of-core producer's particles come from: a set read in passes, a run at a time (a binary PLY or
//! columns of text streamed from disk, or a set in memory).

use crate::error::GeometryError;
use crate::formats::ply::PlyPointStream;
use crate::formats::xyz::TextPointStream;
use crate::particles::{ParticleSet, RawParticles};

/// A particle set read in passes, a run of particles at a time.
pub trait ParticleChunks: Sync {
    /// Whether the particles carry smoothing lengths, masses and values.
    fn columns(&self) -> [bool; 3];
    /// Calls `f` with consecutive runs of the particles and the index of each run's first.
    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError>;
}

impl ParticleChunks for PlyPointStream {
    fn columns(&self) -> [bool; 3] {
        PlyPointStream::columns(self)
    }

    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        PlyPointStream::for_each_chunk(self, f)
    }
}

/// A set in memory, in runs of 65,536 (for tests, and to compare with the in-memory producer).
impl ParticleChunks for TextPointStream {
    fn columns(&self) -> [bool; 3] {
        TextPointStream::columns(self)
    }

    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        TextPointStream::for_each_chunk(self, f)
    }
}

impl ParticleChunks for ParticleSet {
    fn columns(&self) -> [bool; 3] {
        [!self.smoothing().is_empty(), !self.masses().is_empty(), !self.values().0.is_empty()]
    }

    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        const RUN: usize = 1 << 16;
        let column = |c: &[f32], from: usize, to: usize| if c.is_empty() { Vec::new() } else { c[from..to].to_vec() };
        for from in (0..self.len()).step_by(RUN) {
            let to = (from + RUN).min(self.len());
            let run = RawParticles {
                positions: self.positions()[from..to].to_vec(),
                smoothing: column(self.smoothing(), from, to),
                masses: column(self.masses(), from, to),
                values: column(self.values().0, from, to),
                value_name: self.values().1.to_string(),
            };
            f(from as u64, &run)?;
        }
        Ok(())
    }
}
