//! The GPU's cell solver against its CPU twin, one stage alone: `cell_cubic.wgsl` (the real file, from
//! [`RAY_CASTER_FILES`], compiled alone inside a small compute shader) against
//! `voxstream_render::cell_intersection::CellCubic`, on about 5000 cells.
//!
//! What it guards: the trilinear cell's cubic along a ray (`cell_cubic`, `CellCubic::new`), its monotone pieces
//! (`cubic_pieces`, `CellCubic::extrema`) and its crossings of an isovalue (`cubic_crossings` and `cubic_refine`,
//! `CellCubic::crossings` and `refine`): the first crossing is what an isosurface ray draws, the others what it
//! composites behind it. For every cell:
//! - both sides find the same number of crossings (so the same hit or miss), and the same crossings to within
//!   [`ROOT_TOLERANCE`] of the span; the coefficients agree to [`COEFFICIENT_ULPS`] ulps of their largest term;
//! - the one excuse is rounding where the cell cannot tell: a count may differ only where the cubic (in f64, from
//!   the CPU's coefficients) comes within [`VALUE_TOLERANCE`] of the cell's magnitude to the isovalue at a point
//!   that decides the count (the span's ends and the cubic's extrema: a grazing ray, a double root, a crossing at
//!   an end), and two crossings may lie further apart only where the cubic between them stays that close to the
//!   isovalue (flat or tangent cells, where no f32 evaluation orders them). Excuses are counted and printed;
//! - on a CPU emulation (lavapipe, the CI adapter), which rounds each f32 operation once as the CPU does, the two
//!   must agree bit for bit, excuses or not (measured: 0 of 4943 cells differ).
//!
//! The tolerances are themselves tested, without a GPU, on `emulation.rs`, the shader's solver transliterated
//! operation for operation: in the CPU's arithmetic it is the CPU's solver bit for bit; with the rounding Vulkan
//! allows (division and square root off by 2 ulps, products fused with sums) it passes the tolerances; with a
//! defect (fewer refinement steps, no Illinois step) it fails them.
//!
//! The cells (`cases.rs`): random 16-bit cells crossed by random rays at 10⁻² to 10³ voxels per world unit;
//! rays grazing the isosurface (tangent to the level set: a double root) and nearly grazing it; exactly
//! representable double roots; crossings at a corner, at the span's ends and a hair inside them; isovalues outside
//! the cell's values; degenerate rays and cells (axis-aligned, in a plane, standing still, constant cells, tiny
//! spans, fast and slow rays, three crossings in one cell).
//!
//! Needs a Vulkan adapter, as the image tests (`crates/voxstream/tests/gpu_backend.rs`): CI installs Mesa's
//! lavapipe; without one the GPU test fails and names the packages (it never skips silently).

mod cases;
mod emulation;

use std::sync::mpsc;

use emulation::{Defect, Rounding};
use voxstream_gpu::shader::RAY_CASTER_FILES;
use voxstream_gpu::GpuContext;
use voxstream_render::cell_intersection::CellCubic;
use wgpu::util::DeviceExt;

/// Crossings may differ by this fraction of the span without an excuse (a simple root refined to f32 resolution
/// moves by a few 10⁻⁷ under another rounding).
const ROOT_TOLERANCE: f64 = 1e-5;
/// The excuse's margin, as a fraction of the cell's magnitude (its largest corner, the isovalue and the cubic's
/// terms over the span): sixteen f32 unit roundoffs (2⁻²⁴ each), eight times the least that 40 runs of the emulated
/// GPU rounding needed (2⁻²³; at 2⁻²⁴ one of three fails).
const VALUE_TOLERANCE: f64 = 1.0 / (1u64 << 20) as f64;
/// GPU and CPU coefficients may differ by this many ulps of the largest term summed into them.
const COEFFICIENT_ULPS: f64 = 8.0;

/// A cell and a ray through it: corners (x fastest), cell-local start and rate, isovalue, span length.
#[derive(Clone, Copy, Debug)]
pub struct Case {
    pub corners: [f32; 8],
    pub start: [f32; 3],
    pub rate: [f32; 3],
    pub iso: f32,
    pub length: f32,
}

/// What one side found.
#[derive(Clone, Copy, Debug)]
pub struct Found {
    pub count: usize,
    pub roots: [f32; 3],
    pub coefficients: [f32; 4],
}

/// The harness around `cell_cubic.wgsl`: one invocation per case, 16 floats in, 8 words out.
const HARNESS: &str = "
@group(0) @binding(0) var<storage, read> cases: array<f32>;
@group(0) @binding(1) var<storage, read_write> results: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn twin(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= arrayLength(&cases) / 16u {
        return;
    }
    let at = id.x * 16u;
    var v: array<f32, 8>;
    for (var k = 0u; k < 8u; k++) {
        v[k] = cases[at + k];
    }
    let start = vec3<f32>(cases[at + 8u], cases[at + 9u], cases[at + 10u]);
    let rate = vec3<f32>(cases[at + 11u], cases[at + 12u], cases[at + 13u]);
    let c = cell_cubic(v, start, rate);
    let found = cubic_crossings(c, cases[at + 14u], cubic_pieces(c, cases[at + 15u]));
    let out = id.x * 8u;
    results[out] = found.count;
    for (var k = 0u; k < 3u; k++) {
        results[out + 1u + k] = bitcast<u32>(found.u[k]);
    }
    for (var k = 0u; k < 4u; k++) {
        results[out + 4u + k] = bitcast<u32>(c[k]);
    }
}
";

/// The GPU side: every case through `cell_cubic.wgsl` on the project's adapter ([`GpuContext::new`]).
fn gpu_crossings(cases: &[Case]) -> (Vec<Found>, wgpu::DeviceType) {
    let context = GpuContext::new().unwrap_or_else(|e| {
        panic!("{e}\n(the GPU tests need a Vulkan driver; CI installs Mesa's lavapipe: apt-get install mesa-vulkan-drivers libvulkan1)")
    });
    println!("adapter: {}", context.describe());
    let device = &context.device;
    let (_, cell_cubic) = RAY_CASTER_FILES.iter().find(|(name, _)| *name == "cell_cubic.wgsl").expect("the file");
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("cell_cubic.wgsl twin"),
        source: wgpu::ShaderSource::Wgsl(format!("{cell_cubic}{HARNESS}").into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("cell_cubic.wgsl twin"),
        layout: None,
        module: &module,
        entry_point: Some("twin"),
        compilation_options: Default::default(),
        cache: None,
    });
    let input: Vec<f32> = cases
        .iter()
        .flat_map(|c| c.corners.into_iter().chain(c.start).chain(c.rate).chain([c.iso, c.length]))
        .collect();
    let inputs = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("cases"),
        contents: bytemuck::cast_slice(&input),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let bytes = cases.len() as u64 * 32;
    let results = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("results"),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("cell_cubic.wgsl twin"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: inputs.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: results.as_entire_binding() },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((cases.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&results, 0, &readback, 0, bytes);
    context.queue.submit([encoder.finish()]);
    let (sender, receiver) = mpsc::channel();
    readback.map_async(wgpu::MapMode::Read, .., move |result| {
        let _ = sender.send(result);
    });
    device.poll(wgpu::PollType::wait_indefinitely()).expect("GPU finished");
    if let Some(error) = pollster::block_on(scope.pop()) {
        panic!("the twin shader: {error}");
    }
    receiver.recv().expect("mapping answered").expect("mapped");
    let words: Vec<u32> = bytemuck::cast_slice(&readback.get_mapped_range(..).expect("mapped range")).to_vec();
    let found = words
        .chunks_exact(8)
        .map(|w| Found {
            count: w[0] as usize,
            roots: [1, 2, 3].map(|i| f32::from_bits(w[i])),
            coefficients: [4, 5, 6, 7].map(|i| f32::from_bits(w[i])),
        })
        .collect();
    (found, context.info.device_type)
}

/// The CPU side: the reference.
pub fn cpu_crossings(case: &Case) -> Found {
    let cubic = CellCubic::new(&case.corners, case.start, case.rate);
    let mut roots = [0.0; 3];
    let count = cubic.crossings(case.iso, case.length, &mut roots);
    Found { count, roots, coefficients: cubic.coefficients() }
}

/// The cubic in f64 from the CPU's coefficients, its extrema inside the span, and the cell's magnitude (its largest
/// corner, the isovalue and the cubic's terms over the span): the scale of its f32 rounding.
fn in_f64(case: &Case, c: [f32; 4]) -> (impl Fn(f64) -> f64, f64, Vec<f64>) {
    let c = c.map(f64::from);
    let f = move |u: f64| c[0] + u * (c[1] + u * (c[2] + u * c[3]));
    let l = case.length as f64;
    let largest_corner = case.corners.iter().fold(0.0f64, |m, &v| m.max((v as f64).abs()));
    let terms: f64 = (0..4).map(|i| c[i].abs() * l.powi(i as i32)).sum();
    let magnitude = largest_corner + (case.iso as f64).abs() + terms;
    // f' = c1 + 2c2·u + 3c3·u².
    let (a, b, q) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let mut extrema = Vec::new();
    if a != 0.0 {
        let d = b * b - 4.0 * a * q;
        if d >= 0.0 {
            extrema.extend([(-b - d.sqrt()) / (2.0 * a), (-b + d.sqrt()) / (2.0 * a)]);
        }
    } else if b != 0.0 {
        extrema.push(-q / b);
    }
    extrema.retain(|&u| u > 0.0 && u < l);
    (f, magnitude, extrema)
}

/// The scale of coefficient `i`'s f32 rounding: its largest possible term (`C(3, i)` products of a corner and `i`
/// differences of corners times rates).
fn coefficient_scale(case: &Case, i: usize) -> f64 {
    let largest_corner = case.corners.iter().fold(0.0f64, |m, &v| m.max((v as f64).abs()));
    let rate = case.rate.iter().fold(0.0f64, |m, &r| m.max((r as f64).abs()));
    largest_corner * [1.0, 3.0, 3.0, 1.0][i] * (2.0 * rate).powi(i as i32)
}

/// How one kind of cell fared.
#[derive(Default)]
struct Tally {
    cells: usize,
    hits: usize,
    worst_crossing: f64,
    excused_counts: usize,
    excused_crossings: usize,
}

/// One side's answers against the CPU's.
#[derive(Default)]
struct Report {
    /// Disagreements beyond the tolerances and their excuses.
    failures: Vec<String>,
    /// Cells whose answer differs from the CPU's in some bit (count, crossings or coefficients).
    inexact: Vec<String>,
    tallies: Vec<(&'static str, Tally)>,
    /// The largest crossing difference, as a fraction of the span, and coefficient difference, of its scale.
    max_crossing: f64,
    max_coefficient: f64,
}

impl Report {
    fn print(&self, side: &str) {
        for (kind, t) in &self.tallies {
            println!(
                "{kind:>26}: {:5} cells, {:5} hit (CPU), largest crossing difference {:.2e} of the span, excused: \
                 {} counts, {} crossings",
                t.cells, t.hits, t.worst_crossing, t.excused_counts, t.excused_crossings
            );
        }
        let cells: usize = self.tallies.iter().map(|(_, t)| t.cells).sum();
        println!(
            "{side}: {cells} cells, {} differ from the CPU in some bit; largest crossing difference {:.2e} of the span, \
             largest coefficient difference {:.2e} of its scale; {} disagreements",
            self.inexact.len(),
            self.max_crossing,
            self.max_coefficient,
            self.failures.len()
        );
    }
}

/// Compares `found` with the CPU's answers for `cases` (see the module's documentation for the rules).
fn compare(cases: &[(&'static str, Case)], found: &[Found]) -> Report {
    assert_eq!(found.len(), cases.len());
    let mut report = Report::default();
    for (&(kind, case), g) in cases.iter().zip(found) {
        let c = cpu_crossings(&case);
        let same_bits = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        if g.count != c.count
            || !same_bits(&g.roots[..g.count], &c.roots[..c.count])
            || !same_bits(&g.coefficients, &c.coefficients)
        {
            report.inexact.push(format!("{kind}: found {g:?}, CPU {c:?}; {case:?}"));
        }
        let slot = match report.tallies.iter().position(|(k, _)| *k == kind) {
            Some(slot) => slot,
            None => {
                report.tallies.push((kind, Tally::default()));
                report.tallies.len() - 1
            }
        };
        let tally = &mut report.tallies[slot].1;
        tally.cells += 1;
        tally.hits += (c.count > 0) as usize;
        for i in 0..4 {
            let scale = coefficient_scale(&case, i);
            let difference = (g.coefficients[i] as f64 - c.coefficients[i] as f64).abs();
            if difference > 0.0 {
                report.max_coefficient = report.max_coefficient.max(difference / scale);
            }
            if difference > COEFFICIENT_ULPS * f32::EPSILON as f64 * scale {
                let (found, cpu) = (g.coefficients, c.coefficients);
                report.failures.push(format!("{kind}: coefficients {found:?}, CPU {cpu:?}; {case:?}"));
            }
        }
        let (f, magnitude, extrema) = in_f64(&case, c.coefficients);
        let tolerance = VALUE_TOLERANCE * magnitude;
        let iso = case.iso as f64;
        if g.count != c.count {
            // Excused only where the cubic touches the isovalue, within rounding, where the count is decided.
            let deciding = [0.0, case.length as f64].into_iter().chain(extrema.iter().copied());
            let margin = deciding.map(|u| (f(u) - iso).abs()).fold(f64::INFINITY, f64::min);
            if margin <= tolerance {
                tally.excused_counts += 1;
            } else {
                report.failures.push(format!(
                    "{kind}: {} crossings {:?}, CPU {} {:?}; nearest |f − iso| {margin:.3e} (excused below \
                     {tolerance:.3e}); {case:?}",
                    g.count,
                    &g.roots[..g.count.min(3)],
                    c.count,
                    &c.roots[..c.count],
                ));
            }
            continue;
        }
        for (&gu, &cu) in g.roots[..g.count].iter().zip(&c.roots[..c.count]) {
            let relative = (gu as f64 - cu as f64).abs() / (case.length as f64).max(f64::MIN_POSITIVE);
            report.max_crossing = report.max_crossing.max(relative);
            tally.worst_crossing = tally.worst_crossing.max(relative);
            if relative <= ROOT_TOLERANCE {
                continue;
            }
            // Excused only where the cubic stays within rounding of the isovalue between the two.
            let (lo, hi) = (gu.min(cu) as f64, gu.max(cu) as f64);
            let between = [lo, hi].into_iter().chain(extrema.iter().copied().filter(|&u| u > lo && u < hi));
            if between.map(|u| (f(u) - iso).abs()).fold(0.0, f64::max) <= tolerance {
                tally.excused_crossings += 1;
            } else {
                let failure = format!("{kind}: crossing {gu}, CPU {cu} ({relative:.2e} of the span); {case:?}");
                report.failures.push(failure);
            }
        }
    }
    report
}

fn first_lines(lines: &[String]) -> String {
    lines[..lines.len().min(20)].join("\n")
}

#[test]
fn the_gpu_finds_the_crossings_the_cpu_finds() {
    let cases = cases::cases();
    assert!(cases.len() >= 4000, "{} cases", cases.len());
    let (gpu, device_type) = gpu_crossings(&cases.iter().map(|&(_, c)| c).collect::<Vec<_>>());
    let report = compare(&cases, &gpu);
    report.print("GPU");
    assert!(report.failures.is_empty(), "{} disagreements:\n{}", report.failures.len(), first_lines(&report.failures));
    // A CPU emulation (lavapipe, CI's adapter) computes f32 as the CPU does, each operation rounded once: there the
    // twin must agree bit for bit, which also catches changes the excuses pass (a crossing's `≥` made `>` differs
    // only where f equals the isovalue exactly, which the excuse for counts allows).
    if device_type == wgpu::DeviceType::Cpu {
        let inexact = &report.inexact;
        assert!(inexact.is_empty(), "{} cells differ on a CPU emulation:\n{}", inexact.len(), first_lines(inexact));
    }
}

/// The emulation of `cell_cubic.wgsl` in the CPU's arithmetic is the CPU's solver, bit for bit: it is a faithful
/// transliteration, so what the next tests learn from it holds for the shader.
#[test]
fn the_emulation_is_the_shader_in_the_cpu_arithmetic() {
    let cases = cases::cases();
    let mut exact = Rounding::exact();
    let found: Vec<Found> =
        cases.iter().map(|(_, case)| emulation::crossings(&mut exact, Defect::None, case)).collect();
    let report = compare(&cases, &found);
    assert!(report.inexact.is_empty(), "{}", first_lines(&report.inexact));
}

/// The tolerances pass a GPU that rounds as Vulkan allows (division and square root off by up to 2 ulps, products
/// fused with sums): the twin test does not fail on hardware for rounding alone.
#[test]
fn the_tolerances_pass_a_gpu_rounding_as_vulkan_allows() {
    let cases = cases::cases();
    for seed in 1..=3 {
        let mut rounding = Rounding::gpu(seed);
        let found: Vec<Found> =
            cases.iter().map(|(_, case)| emulation::crossings(&mut rounding, Defect::None, case)).collect();
        let report = compare(&cases, &found);
        report.print(&format!("emulated GPU rounding (seed {seed})"));
        assert!(report.inexact.len() > cases.len() / 10, "the emulation rounds differently from the CPU");
        assert!(report.failures.is_empty(), "seed {seed}:\n{}", first_lines(&report.failures));
    }
}

/// The tolerances fail a solver that is wrong, not only rounded differently: fewer refinement steps, or plain
/// regula falsi.
#[test]
fn the_tolerances_fail_a_wrong_solver() {
    let cases = cases::cases();
    for defect in [Defect::RefineIterations(8), Defect::NoIllinois] {
        let mut rounding = Rounding::gpu(7);
        let found: Vec<Found> =
            cases.iter().map(|(_, case)| emulation::crossings(&mut rounding, defect, case)).collect();
        let report = compare(&cases, &found);
        println!("{defect:?}: {} disagreements", report.failures.len());
        assert!(report.failures.len() > 10, "{defect:?}: {} disagreements", report.failures.len());
    }
}
