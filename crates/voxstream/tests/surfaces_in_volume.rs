//! Isosurfaces inside a volume rendering (issue 11's "fog plus a surface"): the composite against its closed form
//! through uniform fog, the surfaces unchanged bit for bit when the volume is invisible, the volume rendering's image
//! when no surface is crossed, culling that changes no bit, and the refusal of an empty surface list.

mod common;

use glam::DVec3;
use voxstream::scenes::builtin;
use voxstream_core::{NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_procedural::brick_fill::fill_brick;
use voxstream_render::{psnr, Camera, Image, IsoSurface, RenderSettings, Shading, TransferFunction};

const SIZE: u32 = 64;

/// A ball of radius `R` around `C` in the unit cube: f = ½ + (R − |p − C|)/W, clamped to [0, 1] by the bricks, so
/// f ≥ ½ inside; bricks of 16³ down to level 4 (256³).
struct Ball;

const C: DVec3 = DVec3::new(0.5, 0.5, 0.5);
const R: f64 = 0.3;
const W: f64 = 0.1;

impl Producer for Ball {
    fn shape(&self) -> TreeShape {
        TreeShape::new(2, 16, 4).expect("shape")
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        fill_brick(&self.shape(), &key, voxels, |p| 0.5 + (R - (p - C).length()) / W);
        Ok(Produced { content: NodeContent::Brick, is_terminal: key.level >= 4 })
    }
}

/// Converges one frame of `producer` under `tf` and `settings`.
fn frame<P: Producer>(producer: P, tf: &TransferFunction, settings: RenderSettings, camera: &Camera) -> (Image, u64) {
    let mut session = Session::new(producer, tf, settings, 256 << 20, LoopLimits::default()).expect("session");
    let result = session.render(camera, Mode::Converged).expect("render");
    assert!(result.is_converged(), "not converged after {} passes", result.passes);
    (result.image, result.samples)
}

/// The largest difference of one channel (colour or opacity) of one pixel between two images.
fn worst_channel_difference(a: &Image, b: &Image) -> f32 {
    a.pixels.iter().zip(&b.pixels).flat_map(|(p, q)| (0..4).map(|c| (p[c] - q[c]).abs())).fold(0.0, f32::max)
}

const SURFACE_COLOR: [f32; 3] = [0.9, 0.75, 0.65];
const FOG_COLOR: [f64; 3] = [0.2, 0.4, 0.8];

#[test]
fn a_surface_behind_uniform_fog_is_dimmed_by_the_closed_form_transmittance() {
    // The same opacity at every value: σ = −ln(1 − a) per unit of length everywhere in the cube, so a ray's fog in
    // front of the ball (or through the whole cube) is 1 − exp(−σ·length), and the opaque ball behind it shows with
    // the rest: colour = fog·(1 − T) + T·surface.
    let a = 0.5;
    let sigma = -(1.0f64 - a).ln();
    let [r, g, b] = FOG_COLOR;
    let tf = TransferFunction::new(vec![[0.0, r, g, b, a], [1.0, r, g, b, a]], Some(1.0)).expect("tf");
    let settings = RenderSettings {
        width: SIZE,
        height: SIZE,
        shading: Shading::None,
        surfaces: vec![IsoSurface { value: 0.5, color: SURFACE_COLOR, opacity: 1.0 }],
        surfaces_in_volume: true,
        ..RenderSettings::default()
    };
    let camera = Camera { eye: [0.5, 0.5, 2.2], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 40.0 };
    let (image, _) = frame(Ball, &tf, settings, &camera);
    let eye = DVec3::from(camera.eye);
    let (mut through_fog_only, mut onto_the_ball, mut worst) = (0, 0, 0.0f64);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let d = common::pixel_direction(&camera, x, y, SIZE, SIZE);
            let Some((t_in, t_out)) = common::ray_box(eye, d, DVec3::ZERO, 1.0) else { continue };
            // The ray's nearest approach to the ball's centre decides: clearly through it or clearly past it.
            let along = (C - eye).dot(d);
            let miss = ((C - eye) - d * along).length();
            let pixel = image.pixels[(y * SIZE + x) as usize];
            let expected: [f64; 4] = if miss < R - 0.01 {
                let t_hit = along - (R * R - miss * miss).sqrt();
                let fog = 1.0 - (-sigma * (t_hit - t_in)).exp();
                onto_the_ball += 1;
                let c = |i: usize| FOG_COLOR[i] * fog + (1.0 - fog) * SURFACE_COLOR[i] as f64;
                [c(0), c(1), c(2), 1.0]
            } else if miss > R + 0.01 {
                let fog = 1.0 - (-sigma * (t_out - t_in)).exp();
                through_fog_only += 1;
                [FOG_COLOR[0] * fog, FOG_COLOR[1] * fog, FOG_COLOR[2] * fog, fog]
            } else {
                continue;
            };
            for (c, e) in pixel.iter().zip(expected) {
                worst = worst.max((*c as f64 - e).abs());
            }
        }
    }
    println!("{onto_the_ball} rays onto the ball, {through_fog_only} through fog only: worst error {worst:.2e}");
    assert!(onto_the_ball > 400 && through_fog_only > 400, "{onto_the_ball} / {through_fog_only} rays checked");
    // The fog's length is counted in whole steps of at most half a voxel of level 2 (1/128): ≤ 0.7·σ/128 in opacity.
    assert!(worst < 6e-3, "worst channel error {worst}");
}

/// The built-in shell's two nested surfaces (the outer one translucent), Phong-lit, with `tf`'s volume around them.
fn shell(tf: &TransferFunction, adjust: impl FnOnce(&mut RenderSettings)) -> (Image, u64) {
    let scene = builtin("shell").expect("shell");
    let mut settings = RenderSettings {
        width: SIZE,
        height: SIZE,
        shading: Shading::Phong,
        light_direction: Some([0.3, 0.8, 0.5]),
        surfaces: vec![
            IsoSurface { value: 0.5, color: [0.55, 0.7, 0.95], opacity: 0.4 },
            IsoSurface { value: 0.9, color: [0.95, 0.8, 0.6], opacity: 1.0 },
        ],
        surfaces_in_volume: true,
        ..RenderSettings::default()
    };
    adjust(&mut settings);
    frame(scene.producer, tf, settings, &scene.camera)
}

/// A volume visible only in the shell's tails (values 0.05–0.4): around the surfaces, not on them.
fn tails() -> TransferFunction {
    TransferFunction::new(
        vec![
            [0.0, 0.2, 0.4, 0.8, 0.0],
            [0.05, 0.2, 0.4, 0.8, 0.0],
            [0.2, 0.3, 0.6, 0.9, 0.6],
            [0.4, 0.2, 0.4, 0.8, 0.0],
        ],
        Some(0.05),
    )
    .expect("tf")
}

#[test]
fn an_invisible_volume_leaves_the_surfaces_bit_for_bit() {
    let transparent = TransferFunction::new(vec![[0.0, 1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 1.0, 1.0, 0.0]], None).unwrap();
    let (alone, cells_alone) = shell(&transparent, |s| s.surfaces_in_volume = false);
    // (The cells examined may differ: with a volume, no coarse subtree is skipped whole, so segments split where
    // the surfaces alone would not split them; the crossings are the same.)
    let (inside, _) = shell(&transparent, |_| {});
    assert!(alone.pixels.iter().filter(|p| p[3] > 0.1).count() > (SIZE * SIZE / 4) as usize);
    assert!(alone.pixels == inside.pixels, "an invisible volume changed the surfaces");
    // A visible one changes them: more cells (its blocks are not culled) and other pixels.
    let (fogged, cells_fogged) = shell(&tails(), |_| {});
    let changed = fogged.pixels.iter().zip(&alone.pixels).filter(|(a, b)| a != b).count();
    assert!(changed > (SIZE * SIZE / 8) as usize, "the volume changed only {changed} pixels");
    assert!(cells_fogged > cells_alone, "{cells_fogged} cells with the volume, {cells_alone} without");
}

#[test]
fn culling_changes_no_bit_of_surfaces_in_a_volume() {
    let (culled, cells_culled) = shell(&tails(), |s| s.shadows = true);
    let (unculled, cells_unculled) = shell(&tails(), |s| {
        s.shadows = true;
        s.skip_empty_space = false;
    });
    let differing = culled.pixels.iter().zip(&unculled.pixels).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{differing} pixels differ with culling on");
    assert!(cells_culled < cells_unculled, "culling skipped nothing: {cells_culled} vs {cells_unculled}");
}

#[test]
fn with_no_surface_crossed_the_volume_is_the_volume_renderings() {
    // An isovalue above every value of the data: no crossing, only the volume. The volume renderer blends each
    // sample with the parent level (quadrilinear) where the cone's level lies between two; this integrand takes
    // the brick at the cone's level alone, so the images agree to within that filtering.
    let tf = tails();
    let (volume, _) = shell(&tf, |s| {
        s.surfaces.clear();
        s.surfaces_in_volume = false;
    });
    let (inside, _) = shell(&tf, |s| {
        s.surfaces.truncate(1);
        s.surfaces[0].value = 2.0;
    });
    let covered = volume.pixels.iter().filter(|p| p[3] > 0.05).count();
    assert!(covered > (SIZE * SIZE / 4) as usize, "only {covered} pixels show the volume");
    let db = psnr(&volume.to_rgb8(), &inside.to_rgb8());
    println!("no surface crossed: {db:.1} dB against the volume rendering");
    assert!(db > 50.0, "{db:.1} dB against the volume rendering");
    // At the finest level everywhere (a level-of-detail bias far above it) neither blends levels: the same samples
    // at the same places, the same values to rounding, so nearly the same image.
    let finest = |s: &mut RenderSettings| s.lod_bias = 8.0;
    let (volume, _) = shell(&tf, |s| {
        finest(s);
        s.surfaces.clear();
        s.surfaces_in_volume = false;
    });
    let (inside, _) = shell(&tf, |s| {
        finest(s);
        s.surfaces.truncate(1);
        s.surfaces[0].value = 2.0;
    });
    let worst = worst_channel_difference(&volume, &inside);
    println!("no surface crossed, finest level: worst channel difference {worst:.2e}");
    assert!(worst < 1e-5, "worst channel difference {worst}");
}

/// A ramp along x, `f = clamp(2.5·x − 0.75, 0, 1)`: constant nodes (0 below x = 0.3, 1 above x = 0.7, with a
/// voxel's margin) and bricks between, where every level's trilinear interpolant is the same linear function. Above
/// x = ½ the bricks end at level 2, so a ray coming from there into finer bricks takes shorter steps.
struct Ramp;

impl Producer for Ramp {
    fn shape(&self) -> TreeShape {
        TreeShape::new(2, 16, 4).expect("shape")
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        let shape = self.shape();
        let ([x, _, _], size) = key.bounds(&shape);
        let margin = shape.voxel_size(key.level);
        let content = if x + size + margin < 0.3 {
            NodeContent::Constant(0.0)
        } else if x - margin > 0.7 {
            NodeContent::Constant(1.0)
        } else {
            fill_brick(&shape, &key, voxels, |p| (2.5 * p.x - 0.75).clamp(0.0, 1.0));
            NodeContent::Brick
        };
        Ok(Produced { content, is_terminal: key.level >= 4 || (key.level >= 2 && x >= 0.5) })
    }
}

#[test]
fn the_volume_is_sampled_where_the_volume_renderer_samples_it() {
    // On the ramp, blending a brick with its parent changes no value where the transfer function varies (the field
    // is linear there; its kinks lie where the function is flat), so the volume rendering and this integrand with
    // no surface crossed must agree, with the cone's level of detail: the same steps (which shrink along rays that
    // come nearer), the same sample positions after step changes, and the constant nodes integrated from the end
    // of the last sample's step (measured: 3e-7; without taking the samples that fall before a segment whose step
    // shrank, or integrating constant nodes from their entry, 1e-3 and more).
    let tf = TransferFunction::new(
        vec![
            [0.0, 0.2, 0.4, 0.8, 0.3],
            [0.1, 0.2, 0.4, 0.8, 0.3],
            [0.9, 0.9, 0.6, 0.3, 0.05],
            [1.0, 0.9, 0.6, 0.3, 0.05],
        ],
        Some(0.02),
    )
    .expect("tf");
    let camera = Camera { eye: [1.3, 0.45, 0.6], target: [-0.2, 0.55, 0.45], up: [0.0, 0.0, 1.0], fov: 60.0 };
    let settings = RenderSettings { width: SIZE, height: SIZE, shading: Shading::None, ..RenderSettings::default() };
    let (volume, _) = frame(Ramp, &tf, settings.clone(), &camera);
    let surfaces = vec![IsoSurface { value: 2.0, color: SURFACE_COLOR, opacity: 1.0 }];
    let (inside, _) = frame(Ramp, &tf, RenderSettings { surfaces, surfaces_in_volume: true, ..settings }, &camera);
    let seen = volume.pixels.iter().filter(|p| p[3] > 0.2).count();
    assert!(seen > (SIZE * SIZE / 2) as usize, "only {seen} pixels show the volume");
    let worst = worst_channel_difference(&volume, &inside);
    println!("the ramp, no surface crossed: worst channel difference {worst:.2e}");
    assert!(worst < 1e-5, "worst channel difference {worst}");
}

#[test]
fn a_volume_around_no_surface_is_refused() {
    let settings = RenderSettings { surfaces_in_volume: true, ..RenderSettings::default() };
    let error = settings.validate().expect_err("refused").to_string();
    assert!(error.contains("at least one isosurface"), "{error}");
}
