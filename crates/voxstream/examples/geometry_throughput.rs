//! Bricks per second made by the mesh and particle producers (BENCHMARKS.md, "Meshes and particles").
//!
//! `cargo run --release --example geometry_throughput -- FILE [LEVEL] [--amplify K]`: reads FILE, then produces every
//! brick of LEVEL that the oracle cannot answer (the bricks a converged view of the whole object needs at that
//! level), on all threads, and prints the opening time, the bricks, their time and bricks per second.

use std::path::PathBuf;
use std::time::Instant;

use rayon::prelude::*;
use voxstream_core::{NodeKey, Producer};
use voxstream_geometry::formats::{read_geometry, RawGeometry};
use voxstream_geometry::{
    Amplification, MeshProducer, MeshTreeSettings, ParticleProducer, ParticleSet, ParticleTreeSettings, TriangleMesh,
};

fn measure(producer: &impl Producer, level: u32) {
    let shape = producer.shape();
    let per_axis = shape.nodes_per_axis(level);
    let started = Instant::now();
    let keys: Vec<NodeKey> = (0..per_axis.pow(3))
        .into_par_iter()
        .map(|i| NodeKey { level, ijk: [i % per_axis, i / per_axis % per_axis, i / per_axis / per_axis] })
        .filter(|key| producer.oracle(*key).is_none())
        .collect();
    let oracle_s = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let voxels: usize = keys
        .par_iter()
        .map_init(
            || vec![0u16; shape.voxels_per_brick()],
            |buffer, key| {
                producer.produce(*key, buffer).expect("produce");
                buffer.len()
            },
        )
        .sum();
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "level {level} ({}^3 voxels): {} bricks of {}^3 in {seconds:.2} s on {} threads: {:.0} bricks/s, {:.1} Mvoxels/s \
         (oracle over all {} nodes: {oracle_s:.2} s)",
        per_axis * u64::from(shape.brick_size),
        keys.len(),
        shape.stored_brick_size(),
        rayon::current_num_threads(),
        keys.len() as f64 / seconds,
        voxels as f64 / seconds / 1e6,
        per_axis.pow(3)
    );
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let file = PathBuf::from(
        args.first().ok_or("usage: geometry_throughput FILE [LEVEL] [--amplify K] [--smoothing-scale F]")?,
    );
    let level: u32 = args.get(1).filter(|a| !a.starts_with("--")).map(|a| a.parse()).transpose()?.unwrap_or(6);
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).map(|k| k.parse::<f64>());
    let amplify = flag("--amplify");
    let smoothing_scale = flag("--smoothing-scale").transpose()?.unwrap_or(1.0);
    let started = Instant::now();
    match read_geometry(&file)? {
        RawGeometry::Mesh(raw) => {
            let mesh = TriangleMesh::new(raw)?;
            let read_s = started.elapsed().as_secs_f64();
            let amplify = amplify.transpose()?.map(|k| Amplification::with_amplitude(k * 0.8));
            let producer = MeshProducer::new(&mesh, MeshTreeSettings { amplify, ..MeshTreeSettings::default() })?;
            println!(
                "{}: {} triangles, read in {read_s:.2} s, distance index in {:.2} s",
                file.display(),
                mesh.triangles().len(),
                started.elapsed().as_secs_f64() - read_s
            );
            measure(&producer, level);
        }
        RawGeometry::Particles(raw) => {
            let particles = ParticleSet::new(raw)?;
            let read_s = started.elapsed().as_secs_f64();
            let settings = ParticleTreeSettings { smoothing_scale, ..ParticleTreeSettings::default() };
            let producer = ParticleProducer::new(&particles, settings)?;
            println!(
                "{}: {} particles, read in {read_s:.2} s, grid in {:.2} s",
                file.display(),
                particles.len(),
                started.elapsed().as_secs_f64() - read_s
            );
            measure(&producer, level);
        }
    }
    Ok(())
}
