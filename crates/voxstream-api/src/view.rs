//! What a view asks of a source: the transfer function, isosurfaces, shading, light, sampling and camera, as typed
//! options, checked and applied over the source's defaults ([`prepare_view`]). The CLI's flags and the Python
//! module's keyword arguments are turned into [`ViewOptions`]; their mistakes get the same one-line messages, which
//! name the CLI's flags.
//!
//! Isosurfaces are Knoll et al.'s exact ray–isosurface intersections over min/max hierarchies (`voxstream-render`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use voxstream_core::json_limits::read_json_file;
use voxstream_render::{
    Camera, ClipPlane, IsoSurface, Projection, RenderSettings, Shading, SurfaceNormals, TransferFunction,
    VolumePlacement, MAX_SURFACES,
};
use voxstream_store::Orientation;

use crate::camera_path::read_camera_file;
use crate::camera_presets::{preset_camera, CameraTurn, ViewDirection};
use crate::defaults::{check_placement, shown_number};
use crate::source::SourceMeta;

/// Colours of the surfaces when none are given, in order (linear RGB).
pub const PALETTE: [[f32; 3]; MAX_SURFACES] = [
    [0.9, 0.75, 0.65],
    [0.55, 0.7, 0.95],
    [0.95, 0.9, 0.5],
    [0.6, 0.9, 0.6],
    [0.95, 0.55, 0.55],
    [0.75, 0.6, 0.95],
    [0.5, 0.9, 0.9],
    [0.9, 0.9, 0.9],
];

/// Where the transfer function comes from.
#[derive(Clone, Debug, Default)]
pub enum TransferFunctionChoice {
    /// The source's default.
    #[default]
    Default,
    /// A file: voxstream's JSON, or a ParaView colour-map preset rescaled onto the data's value range (`--tf FILE`).
    File(PathBuf),
    /// One built by the caller (control points in data values).
    Given(TransferFunction),
}

/// The isosurfaces a view draws (empty `values`: none, the volume).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IsoOptions {
    /// Isovalues in data values (`--iso`).
    pub values: Vec<f64>,
    /// One linear-RGB colour per value, or none for the palette (`--iso-color`).
    pub colors: Vec<[f64; 3]>,
    /// One opacity in (0, 1] per value, or none for opaque surfaces (`--iso-opacity`).
    pub opacities: Vec<f32>,
    /// Shadows cast towards the light (`--shadows`; needs a light).
    pub shadows: bool,
    /// Normals from central differences instead of the trilinear cell's gradient (`--normals central`).
    pub central_normals: bool,
}

/// A camera: a file's, or the source's default, with parts set over it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraOptions {
    /// A camera file (`--camera FILE`); `None`: the source's default view.
    pub file: Option<PathBuf>,
    /// A whole camera given by the caller, over the file or the default.
    pub camera: Option<Camera>,
    /// The eye's position over it (`--eye`).
    pub eye: Option<[f64; 3]>,
    /// The point looked at (`--target`).
    pub target: Option<[f64; 3]>,
    /// The up direction (`--up`).
    pub up: Option<[f64; 3]>,
    /// The vertical field of view, degrees (`--fov`).
    pub fov: Option<f64>,
    /// Frame the volume looking along an axis (`--view`), in place of the file or the default.
    pub preset: Option<ViewDirection>,
    /// Turns and moves it around its target, last (`--azimuth`, `--elevation`, `--zoom`).
    pub turn: CameraTurn,
}

/// What a view asks of a source; the defaults are `voxstream render`'s.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// The transfer function.
    pub transfer_function: TransferFunctionChoice,
    /// The isosurfaces.
    pub iso: IsoOptions,
    /// Shading (`None`: Phong for surfaces, else the source's).
    pub shading: Option<Shading>,
    /// Direction towards the light (`None`: the source's, else a headlight).
    pub light: Option<[f64; 3]>,
    /// Background colour, linear RGB.
    pub background: [f64; 3],
    /// Sample spacing as a fraction of the voxel size (`--step`).
    pub step: f64,
    /// Pre-integrated segments between samples (`--preintegrate`).
    pub preintegrate: bool,
    /// The error-bounded adaptive step's tolerance (`--adaptive-step TOLERANCE`); `None`: not given, so volumes take
    /// the adaptive step at [`voxstream_render::adaptive_step::DEFAULT_TOLERANCE`] unless `faithful`.
    pub adaptive_step: Option<f64>,
    /// Fixed steps of `step` everywhere (`--faithful`): no adaptive step, today's reference-quality march.
    pub faithful: bool,
    /// Level-of-detail bias, levels (`--lod-bias`; positive is coarser).
    pub lod_bias: f64,
    /// Colour each brick by its level (`--colour-by-level`).
    pub colour_by_level: bool,
    /// The camera.
    pub camera: CameraOptions,
    /// Only this box of a store's level-0 samples, `[lower, upper)` along x, y, z (`None`: all of it): the rays
    /// are clipped to it, so a render of one piece of a volume leaves the rest transparent (sort-last rendering,
    /// `voxstream.render_sort_last`). Pieces split at faces of the tree's nodes sample where a render of the whole
    /// volume samples.
    pub region: Option<[[u64; 3]; 2]>,
    /// Compositing, or the largest, smallest or mean value along each ray (`--projection`).
    pub projection: Projection,
    /// Half-spaces of the world that are kept (`--clip-plane`).
    pub clip_planes: Vec<ClipPlane>,
    /// A store's plane of samples, drawn alone and face-on (`--slice z=K`; see [`crate::slices`]).
    pub slice: Option<crate::slices::Slice>,
    /// A plane of samples drawn with the volume (its slab's two planes): set from `slice` when it is drawn with the
    /// volume ([`crate::slices`]), not given directly.
    pub volume_slice: Option<[ClipPlane; 2]>,
}

impl Default for ViewOptions {
    fn default() -> Self {
        ViewOptions {
            width: 512,
            height: 512,
            transfer_function: TransferFunctionChoice::Default,
            iso: IsoOptions::default(),
            shading: None,
            light: None,
            background: [0.0; 3],
            step: RenderSettings::default().step_factor,
            preintegrate: RenderSettings::default().preintegrated,
            adaptive_step: None,
            faithful: false,
            lod_bias: RenderSettings::default().lod_bias,
            colour_by_level: false,
            camera: CameraOptions::default(),
            region: None,
            projection: Projection::Composite,
            clip_planes: Vec::new(),
            slice: None,
            volume_slice: None,
        }
    }
}

/// The transfer function, settings and camera a view makes of a source's defaults.
#[derive(Clone, Debug)]
pub struct PreparedView {
    /// The view's transfer function, or the source's.
    pub transfer_function: TransferFunction,
    /// The render settings.
    pub settings: RenderSettings,
    /// The camera.
    pub camera: Camera,
    /// Whether isosurfaces are drawn (instead of the volume, or inside it with a transfer function).
    pub drawing_surfaces: bool,
    /// The adaptive step's tolerance volumes take when no isosurface is drawn (`settings.adaptive_step` is `None`
    /// while surfaces are): a front end that turns surfaces off again (the viewer's `iso` panel) uses it.
    pub volume_adaptive_step: Option<f64>,
}

/// Checks one isovalue against the data's `value_range`; `given` names where it came from (`--iso`, or a viewer
/// script's line and command), so every front end refuses the same values alike.
pub fn check_isovalue(value: f64, value_range: [f64; 2], given: &str) -> Result<()> {
    let [lower, upper] = value_range;
    let value_text = shown_number(value);
    if !value.is_finite() {
        bail!("{given} {value_text} is not a finite number");
    }
    if value <= lower || value > upper {
        bail!(
            "{given} {value_text} lies outside the data's values ({lower} to {upper}): no surface can appear there; pick a \
             value between them (see `voxstream info`)"
        );
    }
    Ok(())
}

/// The surfaces `iso` asks for (empty: volume rendering), checked against the data's `value_range`; `light` is the
/// view's light (shadows need one).
pub fn surfaces(iso: &IsoOptions, light: Option<[f64; 3]>, value_range: [f64; 2]) -> Result<Vec<IsoSurface>> {
    if iso.values.is_empty() {
        if !iso.colors.is_empty() || !iso.opacities.is_empty() || iso.shadows || iso.central_normals {
            bail!("--iso-color, --iso-opacity, --shadows and --normals apply to isosurfaces: add --iso VALUE");
        }
        return Ok(Vec::new());
    }
    if iso.values.len() > MAX_SURFACES {
        bail!("--iso names {} values; at most {MAX_SURFACES} surfaces are drawn at once", iso.values.len());
    }
    for &value in &iso.values {
        check_isovalue(value, value_range, "--iso")?;
    }
    let colors = match iso.colors.len() {
        0 => PALETTE[..iso.values.len()].to_vec(),
        n if n != iso.values.len() => {
            bail!("--iso-color gives {n} colours for {} isovalues: give one per value", iso.values.len())
        }
        _ => iso.colors.iter().map(|c| c.map(|v| v as f32)).collect(),
    };
    let opacities = match iso.opacities.len() {
        0 => vec![1.0; iso.values.len()],
        n if n != iso.values.len() => {
            bail!("--iso-opacity gives {n} opacities for {} isovalues: give one per value", iso.values.len())
        }
        _ => iso.opacities.clone(),
    };
    if let Some(bad) = opacities.iter().find(|a| !(**a > 0.0 && **a <= 1.0)) {
        bail!("--iso-opacity {bad} is not in (0, 1]");
    }
    if iso.shadows && light.is_none() {
        bail!("--shadows needs a light that is not at the eye: add --light x,y,z (the direction towards the light)");
    }
    Ok(iso
        .values
        .iter()
        .zip(colors)
        .zip(opacities)
        .map(|((&value, color), opacity)| IsoSurface { value, color, opacity })
        .collect())
}

/// The adaptive step's tolerance for `view`: the one given (`--adaptive-step`), none with `--faithful` or where only
/// isosurfaces are drawn (their cell walk has its own exact steps), else the default — volumes trade the fidelity a
/// fixed half-voxel step holds beyond what the eye or the peers show for speed (issue 46: within
/// [`voxstream_render::adaptive_step::DEFAULT_TOLERANCE`] of optical depth per monotone stretch of a ray).
fn step_choice(view: &ViewOptions, drawing_surfaces: bool) -> Result<Option<f64>> {
    match view.adaptive_step {
        Some(_) if view.faithful => {
            bail!("--faithful takes fixed steps and --adaptive-step varies them: give one of the two")
        }
        Some(tolerance) => Ok(Some(tolerance)),
        None if view.faithful || drawing_surfaces => Ok(None),
        None => Ok(Some(voxstream_render::adaptive_step::DEFAULT_TOLERANCE)),
    }
}

/// Applies `view` to `source`'s defaults.
pub fn prepare_view(view: &ViewOptions, source: &SourceMeta) -> Result<PreparedView> {
    // A slice is a view of its own: its slab's clipping planes, the mean projection, the camera along its axis.
    let sliced;
    let view = match view.slice {
        Some(slice) => {
            sliced = crate::slices::slice_view(view, slice, source)?;
            &sliced
        }
        None => view,
    };
    if view.width == 0 || view.height == 0 {
        bail!("image size must be positive, got {}x{}", view.width, view.height);
    }
    if view.projection != Projection::Composite && !view.iso.values.is_empty() {
        bail!(
            "--projection {} draws values along rays, not isosurfaces: drop --iso or --projection",
            view.projection.name()
        );
    }
    let (transfer_function, tf_given) = match &view.transfer_function {
        TransferFunctionChoice::Default => (source.transfer_function.clone(), false),
        TransferFunctionChoice::File(path) => (read_transfer_function(path, source.value_range)?, true),
        TransferFunctionChoice::Given(tf) => (tf.clone(), true),
    };
    let mut surfaces = surfaces(&view.iso, view.light, source.value_range)?;
    if surfaces.is_empty() && !tf_given {
        surfaces = source.default_surfaces.clone();
        // A mesh or molecule is drawn as its surface unless a transfer function is given: say so, rather than
        // naming an --iso the user never gave.
        if !surfaces.is_empty() && view.projection != Projection::Composite {
            bail!(
                "--projection {} draws values along rays, but {} is drawn as an isosurface by default (meshes and \
                 molecules are): add --tf FILE to draw its values as a volume, or drop --projection",
                view.projection.name(),
                source.name
            );
        }
    }
    let drawing_surfaces = !surfaces.is_empty();
    let adaptive_step = step_choice(view, drawing_surfaces)?;
    let volume_adaptive_step = step_choice(view, false)?;
    let settings = RenderSettings {
        width: view.width,
        height: view.height,
        shading: match view.shading {
            Some(shading) => shading,
            None if drawing_surfaces => Shading::Phong,
            None => source.shading,
        },
        surfaces,
        shadows: view.iso.shadows,
        surface_normals: if view.iso.central_normals {
            SurfaceNormals::CentralDifferences
        } else {
            SurfaceNormals::Cell
        },
        // Isosurfaces with a transfer function: the surfaces inside the volume.
        surfaces_in_volume: drawing_surfaces && tf_given,
        light_direction: view.light.or(source.light),
        background: view.background.map(|c| c as f32),
        step_factor: view.step,
        preintegrated: view.preintegrate,
        adaptive_step,
        lod_bias: view.lod_bias,
        colour_by_level: view.colour_by_level,
        placement: region_placement(source, view.region)?,
        projection: view.projection,
        clip_planes: view.clip_planes.clone(),
        volume_slice: view.volume_slice,
        ..RenderSettings::default()
    };
    check_placement(&source.name, &source.placement)?;
    settings.validate()?;
    let camera = apply_camera_options_framing(
        source.camera,
        &view.camera,
        (view.width, view.height),
        &source.name,
        Some(placement_bounds(&settings.placement)),
        source.store.as_ref().and_then(|store| store.info().orientation),
    )?;
    Ok(PreparedView { transfer_function, settings, camera, drawing_surfaces, volume_adaptive_step })
}

/// The source's placement with its clip box narrowed to `region` (level-0 samples, `[lower, upper)`).
fn region_placement(source: &SourceMeta, region: Option<[[u64; 3]; 2]>) -> Result<VolumePlacement> {
    let mut placement = source.placement;
    let Some([lower, upper]) = region else {
        return Ok(placement);
    };
    let Some(store) = &source.store else {
        bail!("{}: a region applies to stores, not to scenes, meshes or particles", source.name);
    };
    let (info, layout) = (store.info(), store.layout());
    if (0..3).any(|a| lower[a] >= upper[a] || lower[a] >= info.dims[a]) {
        bail!(
            "the region {lower:?} to {upper:?} holds none of {}'s samples ({:?}): give lower < upper within them",
            source.name,
            info.dims
        );
    }
    if let Some(a) = (0..3).find(|&a| upper[a] > info.dims[a]) {
        bail!(
            "the region's upper bound {} along {} lies beyond {}'s {} samples there ({:?}): give at most the \
             dimensions `voxstream info` shows",
            upper[a],
            ["x", "y", "z"][a],
            source.name,
            info.dims[a],
            info.dims
        );
    }
    let span = (layout.brick_size << layout.max_tree_level()) as f64;
    for a in 0..3 {
        placement.clip_lower[a] = placement.clip_lower[a].max(lower[a] as f64 / span);
        placement.clip_upper[a] = placement.clip_upper[a].min(upper[a] as f64 / span);
    }
    Ok(placement)
}

/// The camera `options` make of a source's default view `default` (named `name`): a camera file or a whole camera
/// replaces it, then `--eye`, `--target`, `--up` and `--fov` set their parts; checked for a `width × height` image.
pub fn apply_camera_options(
    default: Camera,
    options: &CameraOptions,
    width: u32,
    height: u32,
    name: &str,
) -> Result<Camera> {
    apply_camera_options_framing(default, options, (width, height), name, None, None)
}

/// The world box a placement's clip box covers, `[lower, upper]`.
pub fn placement_bounds(placement: &VolumePlacement) -> [[f64; 3]; 2] {
    let corner = |v: [f64; 3]| -> [f64; 3] { std::array::from_fn(|a| placement.origin[a] + placement.scale[a] * v[a]) };
    [corner(placement.clip_lower), corner(placement.clip_upper)]
}

/// [`apply_camera_options`] where a preset (`--view`) frames `bounds` (the volume's world box; `None`: a preset
/// is refused) of a volume whose anatomical orientation is `orientation` (where known: the anatomical presets).
pub fn apply_camera_options_framing(
    default: Camera,
    options: &CameraOptions,
    (width, height): (u32, u32),
    name: &str,
    bounds: Option<[[f64; 3]; 2]>,
    orientation: Option<Orientation>,
) -> Result<Camera> {
    let mut camera = match &options.file {
        Some(path) => read_camera_file(path)?,
        None => default,
    };
    if let Some(preset) = options.preset {
        if options.file.is_some() || options.camera.is_some() || options.eye.is_some() || options.target.is_some() {
            bail!("--view {} places the camera itself: drop --camera, --eye and --target, or --view", preset.name());
        }
        let Some(bounds) = bounds else { bail!("--view {}: {name} has no box to frame", preset.name()) };
        camera = preset_camera(preset, orientation, name, bounds, (width, height), options.fov.unwrap_or(camera.fov))?;
    }
    if let Some(given) = options.camera {
        camera = given;
    }
    if let Some(eye) = options.eye {
        camera.eye = eye;
    }
    if let Some(target) = options.target {
        camera.target = target;
    }
    if let Some(up) = options.up {
        camera.up = up;
    }
    if let Some(fov) = options.fov {
        camera.fov = fov;
    }
    camera.frame(width, height).with_context(|| format!("invalid camera ({})", camera_origin(options, name)))?;
    camera = options.turn.apply(camera)?;
    camera.frame(width, height).with_context(|| format!("invalid camera ({})", camera_origin(options, name)))?;
    Ok(camera)
}

/// Where the camera came from, for its error: the options that set parts of it over a camera file or the source's
/// default view (e.g. "--eye 1e308,0,0 over sponge's default view").
fn camera_origin(options: &CameraOptions, name: &str) -> String {
    let vector = |v: [f64; 3]| v.map(shown_number).join(",");
    let flags: Vec<String> = [
        options.camera.map(|c| format!("camera eye {} target {}", vector(c.eye), vector(c.target))),
        options.eye.map(|v| format!("--eye {}", vector(v))),
        options.target.map(|v| format!("--target {}", vector(v))),
        options.up.map(|v| format!("--up {}", vector(v))),
        options.fov.map(|f| format!("--fov {}", shown_number(f))),
        options.preset.map(|p| format!("--view {}", p.name())),
        options.turn.azimuth.map(|v| format!("--azimuth {}", shown_number(v))),
        options.turn.elevation.map(|v| format!("--elevation {}", shown_number(v))),
        options.turn.zoom.map(|v| format!("--zoom {}", shown_number(v))),
    ]
    .into_iter()
    .flatten()
    .collect();
    let base = match &options.file {
        Some(path) => format!("--camera {}", path.display()),
        None => format!("{name}'s default view"),
    };
    if flags.is_empty() {
        base
    } else {
        format!("{} over {base}", flags.join(", "))
    }
}

/// Reads a transfer function file: voxstream's JSON, or a ParaView colour-map preset rescaled onto `value_range`.
pub fn read_transfer_function(path: &Path, value_range: [f64; 2]) -> Result<TransferFunction> {
    let text = read_json_file(path, "transfer function")?;
    TransferFunction::from_json_or_paraview(&text, value_range).with_context(|| format!("in {}", path.display()))
}
