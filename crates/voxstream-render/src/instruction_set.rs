//! Which instructions the ray loop is compiled for, chosen at run time.
//!
//! The release build targets x86-64-v2 (SSE4.2), which every x86-64 CPU since 2009 runs. The tile loop and everything
//! inlined into it is compiled a second time for x86-64-v3 (AVX2, FMA, BMI2; three-operand VEX encodings) and picked
//! at run time when the CPU has it, through `pulp`'s safe dispatch (no `unsafe` here). Other architectures (aarch64)
//! build the baseline only. The arithmetic is the same IEEE operations in either version (Rust never fuses a
//! multiply and an add on its own), so the image is the same bytes whichever runs; a test checks it.

/// The build of the ray loop that runs ([`InstructionSet::build`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RayLoopBuild {
    /// The build's baseline (x86-64-v2 on x86-64).
    Baseline,
    /// The x86-64-v3 build (AVX2, FMA, BMI2), with AVX2 gathers of brick corners.
    X86_64V3,
}

/// The instruction set the ray loop uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InstructionSet {
    /// The best the CPU offers (AVX2+FMA on x86-64-v3 CPUs, else the baseline).
    #[default]
    Detect,
    /// The build's baseline (x86-64-v2 here), whatever the CPU.
    Baseline,
}

impl InstructionSet {
    /// The dispatcher to run the tile loop with.
    pub fn arch(self) -> pulp::Arch {
        match self {
            InstructionSet::Detect => pulp::Arch::new(),
            InstructionSet::Baseline => pulp::Arch::Scalar,
        }
    }

    /// Whether the ray loop reads brick corners with AVX2 gathers ([`crate::gathered_corners`]): where it runs the
    /// x86-64-v3 build.
    pub fn gathers(self) -> bool {
        self.build() == RayLoopBuild::X86_64V3
    }

    /// The build of the ray loop that [`InstructionSet::arch`] dispatches to on this CPU.
    pub fn build(self) -> RayLoopBuild {
        match self.arch() {
            #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
            pulp::Arch::V3(_) => RayLoopBuild::X86_64V3,
            _ => RayLoopBuild::Baseline,
        }
    }

    /// What [`InstructionSet::Detect`] finds on this CPU, for reports: `"x86-64-v3 (AVX2+FMA)"` or `"baseline"`.
    pub fn detected() -> &'static str {
        match InstructionSet::Detect.build() {
            RayLoopBuild::X86_64V3 => "x86-64-v3 (AVX2+FMA)",
            RayLoopBuild::Baseline => "baseline",
        }
    }
}
