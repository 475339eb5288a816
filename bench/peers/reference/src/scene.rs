//! The scene file: one JSON document describing the volume, camera, image size, render mode, transfer function or
//! isosurface, and shading of a single reference render. Parsed with serde (unknown fields are errors) and
//! checked for values the renderer cannot use.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Deserialize;

/// Sample type of the raw volume file (little-endian, no header).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dtype {
    U8,
    U16,
    F32,
}

impl Dtype {
    pub fn bytes(self) -> usize {
        match self {
            Dtype::U8 => 1,
            Dtype::U16 => 2,
            Dtype::F32 => 4,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Dtype::U8 => "u8",
            Dtype::U16 => "u16",
            Dtype::F32 => "f32",
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeSpec {
    pub path: PathBuf,
    pub dims: [usize; 3],
    pub dtype: Dtype,
    pub spacing: [f64; 3],
    pub origin: [f64; 3],
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
    /// Vertical field of view in degrees.
    pub fov: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    Volume,
    Isosurface,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shading {
    None,
    Phong,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TfSpec {
    /// `[value, r, g, b, alpha]`, strictly increasing in value.
    pub points: Vec<[f64; 5]>,
    /// World distance over which `alpha` is the accumulated opacity (VTK's ScalarOpacityUnitDistance).
    pub unit_distance: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Phong {
    pub ambient: f64,
    pub diffuse: f64,
    pub specular: f64,
    pub shininess: f64,
}

impl Default for Phong {
    fn default() -> Self {
        Phong { ambient: 0.25, diffuse: 0.75, specular: 0.25, shininess: 16.0 }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IsoSpec {
    pub value: f64,
    pub color: [f64; 3],
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub volume: VolumeSpec,
    pub camera: CameraSpec,
    pub width: usize,
    pub height: usize,
    pub mode: Mode,
    #[serde(default)]
    pub tf: Option<TfSpec>,
    pub shading: Shading,
    #[serde(default)]
    pub phong: Phong,
    /// Direction towards a directional light; `None` means a headlight along `eye - target`.
    #[serde(default)]
    pub light: Option<[f64; 3]>,
    #[serde(default)]
    pub iso: Option<IsoSpec>,
    pub background: [f64; 3],
    #[serde(default = "default_supersample")]
    pub supersample: usize,
    #[serde(default = "default_step_voxels")]
    pub step_voxels: f64,
}

fn default_supersample() -> usize {
    3
}

fn default_step_voxels() -> f64 {
    0.125
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl Scene {
    /// Reads, parses and validates the scene file at `path`.
    pub fn load(path: &Path) -> Result<Scene> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("cannot read scene file {}", path.display()))?;
        let scene = Scene::parse(&text).with_context(|| format!("invalid scene file {}", path.display()))?;
        Ok(scene)
    }

    /// Parses and validates a scene from JSON text.
    pub fn parse(text: &str) -> Result<Scene> {
        let scene: Scene = serde_json::from_str(text)?;
        scene.validate()?;
        Ok(scene)
    }

    /// Checks the values serde cannot: ranges, finiteness, and the fields each mode requires. The transfer
    /// function, camera and volume geometry are checked where they are built.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            bail!("width and height must be in 1..=16384 (got {}x{})", self.width, self.height);
        }
        if self.supersample == 0 || self.supersample > 16 {
            bail!("supersample must be in 1..=16 (got {})", self.supersample);
        }
        if !(self.step_voxels.is_finite() && self.step_voxels >= 1e-4) {
            bail!("step_voxels must be a finite number >= 1e-4 (got {})", self.step_voxels);
        }
        if !finite(&self.background) {
            bail!("background must be finite");
        }
        let p = &self.phong;
        if !finite(&[p.ambient, p.diffuse, p.specular, p.shininess])
            || p.ambient < 0.0
            || p.diffuse < 0.0
            || p.specular < 0.0
            || p.shininess < 0.0
        {
            bail!("phong coefficients must be finite and >= 0");
        }
        if let Some(light) = self.light {
            if !finite(&light) || light == [0.0; 3] {
                bail!("light must be a finite non-zero direction");
            }
        }
        match self.mode {
            Mode::Volume if self.tf.is_none() => bail!("mode \"volume\" requires a \"tf\" object"),
            Mode::Isosurface => match &self.iso {
                None => bail!("mode \"isosurface\" requires an \"iso\" object"),
                Some(iso) if !finite(&[iso.value]) || !finite(&iso.color) => {
                    bail!("iso value and color must be finite")
                }
                Some(_) => {}
            },
            Mode::Volume => {}
        }
        Ok(())
    }
}
