//! Every number the ray caster's WGSL shares with Rust is the same on both sides. No GPU needed: the test reads the
//! shader's text, both variants of it ([`ray_caster_source`] with each [`BrickFiltering`]).
//!
//! What it guards:
//! - **Constants.** Every WGSL `const` of the joined shader (`voxstream-layout`'s `layout.wgsl` and the files of
//!   `src/shader/`) must be listed in [`rust_twins`], with the Rust constant it mirrors, or in [`WGSL_ONLY`], with why
//!   it has none; a listed constant must exist in the WGSL and have the same value: integers exactly, floats to
//!   within one ulp of `f32` (the WGSL literal read as `f32`, against the Rust value rounded to `f32`). So a
//!   constant changed on one side only, or added to the shader without a look at the CPU, fails here. The Rust
//!   values come from where the CPU renderer, the layout crate or the host use them (`voxstream_render`'s step
//!   ladder, shadow rays, cell solver and surface count, `voxstream_core::VOXEL_MAX`, `voxstream_layout`'s flags and
//!   request bits, and `voxstream_gpu::shader_interface`'s pixel flags, workgroup and range packing), never copies.
//! - **Bindings.** Every `@group(g) @binding(b) var… name: type` must be in group [`GROUP`], have the number
//!   [`BINDINGS`] gives `name` (a binding missing from that table fails), and be of the kind of the host's layout
//!   entry with that number ([`layout_entries`]: uniform, storage read or read-write, 3D texture of the right sample
//!   type, sampler); the layout may hold no entry the shader lacks; every name of [`BINDINGS`] is bound by some
//!   variant. With the renderer's layouts and bind groups built from those names, a binding renumbered on either
//!   side fails here instead of at pipeline creation (or, for a kind that still validates, in an image).
//! - **The checks themselves.** The last tests feed the checker altered shaders (a constant's value, a binding's
//!   number, a new binding, a new constant) and require each to be reported, so the checks cannot pass vacuously.
//!
//! The struct layouts shared with the shader are `voxstream-layout`'s `tests/wgsl_mirror.rs` (it checks
//! `layout.wgsl`'s constants too, on its own; this test covers them again as part of the whole shader).

use std::collections::BTreeMap;

use voxstream_gpu::shader::ray_caster_source;
use voxstream_gpu::shader_interface::{
    layout_entries, BINDINGS, GROUP, PIXEL_DONE, PIXEL_MISSED, PIXEL_PENDING, PIXEL_UNTRACED, RANGE_HIGH_SHIFT,
    RANGE_LOW_MASK, WORKGROUP_EDGE,
};
use voxstream_gpu::BrickFiltering;
use voxstream_layout::*;
use voxstream_render::{adaptive_step, cell_intersection, step_table, surface_caster, MAX_SURFACES};

const VARIANTS: [BrickFiltering; 2] = [BrickFiltering::Exact, BrickFiltering::Hardware];

/// A constant's value: WGSL's integers (`u32`, `i32`, abstract) and floats, or a Rust constant's.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Value {
    Int(i128),
    Float(f64),
    Bool(bool),
}

/// The WGSL constants that mirror a Rust constant: name, Rust value.
fn rust_twins() -> Vec<(&'static str, Value)> {
    use Value::{Float, Int};
    let int = |v: u32| Int(v as i128);
    vec![
        // voxstream-layout (layout.wgsl).
        ("NODE_CONSTANT_BIT", int(CONSTANT_BIT)),
        ("NODE_TERMINAL_BIT", int(TERMINAL_BIT)),
        ("NODE_CHILD_MASK", int(CHILD_MASK)),
        ("TABLE_HOLDS_EXTINCTION", int(TABLE_HOLDS_EXTINCTION)),
        ("TABLE_HOLDS_STEP_OPACITY", int(TABLE_HOLDS_STEP_OPACITY)),
        ("REQUEST_PRODUCE", int(REQUEST_PRODUCE)),
        ("REQUEST_SUBDIVIDE", int(REQUEST_SUBDIVIDE)),
        ("REQUEST_KIND_MASK", int(REQUEST_KIND_MASK)),
        ("REQUEST_DEFICIT_SHIFT", int(REQUEST_DEFICIT_SHIFT)),
        ("REQUEST_MAX_DEFICIT", int(REQUEST_MAX_DEFICIT)),
        ("RAY_FRAME_PHONG", int(RAY_FRAME_PHONG)),
        ("RAY_FRAME_STEPS_IGNORE_STAND_INS", int(RAY_FRAME_STEPS_IGNORE_STAND_INS)),
        ("RAY_FRAME_COLOUR_BY_LEVEL", int(RAY_FRAME_COLOUR_BY_LEVEL)),
        ("RAY_FRAME_SKIP_EMPTY_SPACE", int(RAY_FRAME_SKIP_EMPTY_SPACE)),
        ("RAY_FRAME_CENTRAL_NORMALS", int(RAY_FRAME_CENTRAL_NORMALS)),
        ("RAY_FRAME_SHADOWS", int(RAY_FRAME_SHADOWS)),
        ("RAY_FRAME_BLENDING", int(RAY_FRAME_BLENDING)),
        ("RAY_FRAME_SURFACES_IN_VOLUME", int(RAY_FRAME_SURFACES_IN_VOLUME)),
        ("RAY_FRAME_ADAPTIVE_STEP", int(RAY_FRAME_ADAPTIVE_STEP)),
        // The CPU renderer (voxstream-render), which the shader mirrors stage by stage.
        ("STEPS_PER_OCTAVE", Int(step_table::STEPS_PER_OCTAVE as i128)),
        ("LADDER_HALF", Int(step_table::LADDER_HALF as i128)),
        ("RUNG_RATIO", Float(step_table::RUNG_RATIO)),
        ("MAX_STEP_GROWTH", Float(adaptive_step::MAX_STEP_GROWTH)),
        ("SHADOW_CONE", Float(surface_caster::SHADOW_CONE)),
        ("SHADOW_OFFSET", Float(surface_caster::SHADOW_OFFSET)),
        ("REFINE_ITERATIONS", int(cell_intersection::REFINE_ITERATIONS)),
        ("MAX_SURFACES", Int(MAX_SURFACES as i128)),
        // The CPU merges a cell's crossings in `[_; 3 * MAX_SURFACES]` (`Isosurfaces::cell_with`).
        ("MAX_CROSSINGS", Int(3 * MAX_SURFACES as i128)),
        ("VOXEL_MAX", Int(voxstream_core::VOXEL_MAX as i128)),
        // The host (voxstream-gpu's shader_interface.rs).
        ("PIXEL_UNTRACED", int(PIXEL_UNTRACED)),
        ("PIXEL_PENDING", int(PIXEL_PENDING)),
        ("PIXEL_DONE", int(PIXEL_DONE)),
        ("PIXEL_MISSED", int(PIXEL_MISSED)),
        ("WORKGROUP_EDGE", int(WORKGROUP_EDGE)),
        ("RANGE_HIGH_SHIFT", int(RANGE_HIGH_SHIFT)),
        ("RANGE_LOW_MASK", int(RANGE_LOW_MASK)),
    ]
}

/// WGSL constants without a Rust twin, and why.
const WGSL_ONLY: [(&str, &str); 1] =
    [("NO_LEVEL", "the level of a sample colour-by-level leaves untinted; the CPU passes no level (an Option)")];

/// Text with `//` comments removed (the shader has no block comments: [`check_constants`] refuses them).
fn without_comments(text: &str) -> String {
    text.lines().map(|line| line.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
}

/// A WGSL constant expression's tokens: numbers (with their suffix), names, operators and parentheses.
fn tokens(expression: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let chars: Vec<char> = expression.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_alphanumeric() || c == '_' || c == '.' {
            let start = i;
            // A float's exponent may carry a sign: 1e-6.
            while i < chars.len()
                && (chars[i].is_ascii_alphanumeric()
                    || "_.".contains(chars[i])
                    || ("+-".contains(chars[i]) && c.is_ascii_digit() && "eE".contains(chars[i - 1])))
            {
                i += 1;
            }
            out.push(chars[start..i].iter().collect());
        } else if c == '<' && chars.get(i + 1) == Some(&'<') {
            out.push("<<".into());
            i += 2;
        } else {
            out.push(c.to_string());
            i += 1;
        }
    }
    out
}

/// One literal: `12u`, `0x3fu`, `-`-free integers, `1.5`, `2.0f`, `1e-6`, `true`.
fn literal(token: &str) -> Option<Value> {
    match token {
        "true" => return Some(Value::Bool(true)),
        "false" => return Some(Value::Bool(false)),
        _ => {}
    }
    if !token.starts_with(|c: char| c.is_ascii_digit() || c == '.') {
        return None;
    }
    if let Some(hex) = token.strip_prefix("0x").or_else(|| token.strip_prefix("0X")) {
        let digits = hex.trim_end_matches(['u', 'i']);
        return i128::from_str_radix(digits, 16).ok().map(Value::Int);
    }
    let is_float = token.contains(['.', 'e', 'E']) || token.ends_with(['f', 'h']);
    if is_float {
        // Read as f32, as WGSL does for an f32 constant: "exactly as written", rounded once.
        return token.trim_end_matches(['f', 'h']).parse::<f32>().ok().map(|v| Value::Float(v as f64));
    }
    token.trim_end_matches(['u', 'i']).parse::<i128>().ok().map(Value::Int)
}

/// Evaluates a constant expression of literals, earlier constants, unary minus, `* / + - <<` and parentheses.
struct Evaluator<'a> {
    tokens: Vec<String>,
    at: usize,
    known: &'a BTreeMap<String, Value>,
}

impl Evaluator<'_> {
    fn peek(&self) -> Option<&str> {
        self.tokens.get(self.at).map(String::as_str)
    }
    fn next(&mut self) -> Result<String, String> {
        let token = self.tokens.get(self.at).cloned().ok_or("expression ends early")?;
        self.at += 1;
        Ok(token)
    }
    fn shift(&mut self) -> Result<Value, String> {
        let mut value = self.sum()?;
        while self.peek() == Some("<<") {
            self.at += 1;
            value = arithmetic(value, "<<", self.sum()?)?;
        }
        Ok(value)
    }
    fn sum(&mut self) -> Result<Value, String> {
        let mut value = self.product()?;
        while let Some(op @ ("+" | "-")) = self.peek().map(str::to_string).as_deref() {
            self.at += 1;
            value = arithmetic(value, op, self.product()?)?;
        }
        Ok(value)
    }
    fn product(&mut self) -> Result<Value, String> {
        let mut value = self.unary()?;
        while let Some(op @ ("*" | "/")) = self.peek().map(str::to_string).as_deref() {
            self.at += 1;
            value = arithmetic(value, op, self.unary()?)?;
        }
        Ok(value)
    }
    fn unary(&mut self) -> Result<Value, String> {
        if self.peek() == Some("-") {
            self.at += 1;
            return arithmetic(Value::Int(0), "-", self.unary()?);
        }
        let token = self.next()?;
        if token == "(" {
            let value = self.shift()?;
            return if self.next()? == ")" { Ok(value) } else { Err("unbalanced parentheses".into()) };
        }
        literal(&token).or_else(|| self.known.get(&token).copied()).ok_or(format!("unknown term {token:?}"))
    }
}

fn arithmetic(a: Value, op: &str, b: Value) -> Result<Value, String> {
    use Value::{Float, Int};
    Ok(match (a, b) {
        (Int(a), Int(b)) => Int(match op {
            "+" => a + b,
            "-" => a - b,
            "*" => a * b,
            "/" => a / b,
            _ => a << b,
        }),
        (Float(_), _) | (_, Float(_)) if op != "<<" => {
            let as_float = |v: Value| match v {
                Int(i) => Ok(i as f64),
                Float(f) => Ok(f),
                Value::Bool(_) => Err("arithmetic on a bool"),
            };
            let (a, b) = (as_float(a)?, as_float(b)?);
            // f32 arithmetic, as the shader's.
            let (a, b) = (a as f32, b as f32);
            Float(match op {
                "+" => a + b,
                "-" => a - b,
                "*" => a * b,
                _ => a / b,
            } as f64)
        }
        _ => return Err(format!("cannot evaluate {a:?} {op} {b:?}")),
    })
}

/// Every `const NAME[: type] = expression;` of the source, in order, evaluated.
fn parse_constants(source: &str) -> Result<BTreeMap<String, Value>, String> {
    let text = without_comments(source);
    if text.contains("/*") {
        return Err("block comments are not read by this test: use // comments".into());
    }
    let mut constants = BTreeMap::new();
    for statement in text.split(';') {
        // The statement's text after the last brace (a function-scope const follows a `{` or a `}`).
        let statement = statement.rsplit(['{', '}']).next().unwrap_or("");
        let Some(declaration) = statement.trim().strip_prefix("const ") else { continue };
        let (head, expression) = declaration.split_once('=').ok_or(format!("const without value: {declaration}"))?;
        let name = head.split(':').next().unwrap_or("").trim().to_string();
        let mut evaluator = Evaluator { tokens: tokens(expression), at: 0, known: &constants };
        let value = evaluator.shift().map_err(|e| format!("{name}: {e}"))?;
        if evaluator.at != evaluator.tokens.len() {
            return Err(format!("{name}: {expression:?} not read to its end"));
        }
        if constants.insert(name.clone(), value).is_some() {
            return Err(format!("{name} declared twice"));
        }
    }
    Ok(constants)
}

/// Distance in ulps between two finite f32 of the same sign (or zero).
fn ulps(a: f32, b: f32) -> u64 {
    let key = |x: f32| {
        let bits = i64::from(x.to_bits() as i32);
        if bits < 0 {
            i64::from(i32::MIN) - bits
        } else {
            bits
        }
    };
    key(a).abs_diff(key(b))
}

/// What disagrees between the shader's constants and their Rust twins; empty when all agree.
fn check_constants(source: &str, twins: &[(&str, Value)]) -> Vec<String> {
    let wgsl = match parse_constants(source) {
        Ok(constants) => constants,
        Err(e) => return vec![e],
    };
    let mut problems = Vec::new();
    for (name, value) in &wgsl {
        let twin = twins.iter().find(|(n, _)| n == name);
        if twin.is_none() && !WGSL_ONLY.iter().any(|(n, _)| n == name) {
            problems.push(format!("WGSL const {name} = {value:?} has no Rust twin: add it to rust_twins or WGSL_ONLY"));
        }
    }
    for &(name, rust) in twins {
        let Some(&shader) = wgsl.get(name) else {
            problems.push(format!("{name}: no such WGSL const (stale entry in rust_twins?)"));
            continue;
        };
        let agree = match (shader, rust) {
            (Value::Int(a), Value::Int(b)) => a == b,
            (Value::Float(a), Value::Int(b)) => a == b as f64,
            (Value::Float(a), Value::Float(b)) => ulps(a as f32, b as f32) <= 1,
            (Value::Bool(a), Value::Bool(b)) => a == b,
            _ => false,
        };
        if !agree {
            problems.push(format!("{name}: WGSL {shader:?}, Rust {rust:?}"));
        }
    }
    problems
}

/// One `@group(g) @binding(b) var<…> name: type` of the shader.
#[derive(Debug)]
struct Binding {
    group: u32,
    binding: u32,
    name: String,
    /// `uniform`, `storage read`, `storage read_write`, `texture_3d<u32>`, `sampler`, …
    kind: String,
}

fn parse_bindings(source: &str) -> Result<Vec<Binding>, String> {
    let text = without_comments(source);
    let mut bindings = Vec::new();
    for piece in text.split("@group(").skip(1) {
        let number = |s: &str| s.trim().parse::<u32>().map_err(|e| format!("{s:?}: {e}"));
        let (group, rest) = piece.split_once(')').ok_or("@group( without ')'")?;
        let rest = rest.trim_start().strip_prefix("@binding(").ok_or(format!("@group({group}) without @binding"))?;
        let (binding, rest) = rest.split_once(')').ok_or("@binding( without ')'")?;
        let declaration = rest.split(';').next().unwrap_or("").trim();
        let declaration = declaration.strip_prefix("var").ok_or(format!("binding {binding}: not a var"))?;
        let (space, declaration) = match declaration.trim_start().strip_prefix('<') {
            Some(inner) => inner.split_once('>').ok_or("var< without '>'")?,
            None => ("", declaration),
        };
        let (name, ty) = declaration.split_once(':').ok_or(format!("binding {binding}: no type"))?;
        let space: Vec<&str> = space.split(',').map(str::trim).collect();
        let kind = match space[..] {
            ["uniform"] => "uniform".to_string(),
            ["storage"] | ["storage", "read"] => "storage read".to_string(),
            ["storage", "read_write"] => "storage read_write".to_string(),
            [""] => ty.split_whitespace().collect(),
            _ => format!("var<{}>", space.join(", ")),
        };
        bindings.push(Binding { group: number(group)?, binding: number(binding)?, name: name.trim().into(), kind });
    }
    Ok(bindings)
}

/// The kind of a layout entry, named as [`parse_bindings`] names a WGSL declaration's.
fn entry_kind(entry: &wgpu::BindGroupLayoutEntry) -> String {
    use wgpu::{BindingType, BufferBindingType, TextureSampleType, TextureViewDimension};
    match entry.ty {
        BindingType::Buffer { ty: BufferBindingType::Uniform, .. } => "uniform".into(),
        BindingType::Buffer { ty: BufferBindingType::Storage { read_only: true }, .. } => "storage read".into(),
        BindingType::Buffer { ty: BufferBindingType::Storage { read_only: false }, .. } => "storage read_write".into(),
        BindingType::Texture { sample_type, view_dimension: TextureViewDimension::D3, multisampled: false } => {
            match sample_type {
                TextureSampleType::Uint => "texture_3d<u32>".into(),
                TextureSampleType::Sint => "texture_3d<i32>".into(),
                TextureSampleType::Float { .. } => "texture_3d<f32>".into(),
                TextureSampleType::Depth => "texture_depth_3d".into(),
            }
        }
        BindingType::Sampler(wgpu::SamplerBindingType::Comparison) => "sampler_comparison".into(),
        BindingType::Sampler(_) => "sampler".into(),
        ref other => format!("{other:?}"),
    }
}

/// What disagrees between the shader's bindings, [`BINDINGS`] and the host's layout entries; empty when all agree.
fn check_bindings(source: &str, entries: &[wgpu::BindGroupLayoutEntry], table: &[(&str, u32)]) -> Vec<String> {
    let bindings = match parse_bindings(source) {
        Ok(bindings) => bindings,
        Err(e) => return vec![e],
    };
    let mut problems = Vec::new();
    for b in &bindings {
        if b.group != GROUP {
            problems.push(format!("{}: group {}, the host binds group {GROUP}", b.name, b.group));
        }
        match table.iter().find(|(name, _)| *name == b.name) {
            None => problems.push(format!("{} (binding {}) is not in BINDINGS: add it", b.name, b.binding)),
            Some(&(_, number)) if number != b.binding => {
                problems.push(format!("{}: WGSL binding {}, Rust {number}", b.name, b.binding))
            }
            Some(_) => {}
        }
        if bindings.iter().filter(|other| other.binding == b.binding).count() > 1 {
            problems.push(format!("binding {} declared more than once", b.binding));
        }
        match entries.iter().find(|e| e.binding == b.binding) {
            None => problems.push(format!("{} (binding {}): no layout entry", b.name, b.binding)),
            Some(entry) if entry_kind(entry) != b.kind => problems.push(format!(
                "{} (binding {}): WGSL {}, layout {}",
                b.name,
                b.binding,
                b.kind,
                entry_kind(entry)
            )),
            Some(entry) if !entry.visibility.contains(wgpu::ShaderStages::COMPUTE) => {
                problems.push(format!("{}: not visible to compute", b.name))
            }
            Some(_) => {}
        }
    }
    for entry in entries {
        if !bindings.iter().any(|b| b.binding == entry.binding) {
            problems.push(format!("layout entry {} has no WGSL binding", entry.binding));
        }
    }
    problems
}

#[test]
fn every_shared_constant_matches_its_rust_twin() {
    for filtering in VARIANTS {
        let source = ray_caster_source(filtering);
        let problems = check_constants(&source, &rust_twins());
        assert!(problems.is_empty(), "{filtering:?}:\n{}", problems.join("\n"));
    }
    // The workgroup is the host's, by name.
    let source = ray_caster_source(BrickFiltering::Exact);
    assert!(source.contains("@workgroup_size(WORKGROUP_EDGE, WORKGROUP_EDGE, 1)"), "main's workgroup size");
}

#[test]
fn every_binding_matches_the_host_layout() {
    let mut bound = Vec::new();
    for filtering in VARIANTS {
        let source = ray_caster_source(filtering);
        let problems = check_bindings(&source, &layout_entries(filtering), &BINDINGS);
        assert!(problems.is_empty(), "{filtering:?}:\n{}", problems.join("\n"));
        bound.extend(parse_bindings(&source).unwrap().into_iter().map(|b| b.name));
    }
    for (name, _) in BINDINGS {
        assert!(bound.iter().any(|b| b == name), "BINDINGS lists {name}, which no variant of the shader binds");
    }
    let mut numbers: Vec<u32> = BINDINGS.iter().map(|&(_, n)| n).collect();
    numbers.sort_unstable();
    numbers.dedup();
    assert_eq!(numbers.len(), BINDINGS.len(), "BINDINGS gives two names one number");
}

#[test]
fn the_parsers_read_what_the_shader_declares() {
    let constants = parse_constants(&ray_caster_source(BrickFiltering::Exact)).unwrap();
    assert!(constants.len() >= rust_twins().len(), "{constants:?}");
    assert_eq!(constants["NODE_CHILD_MASK"], Value::Int(0x3fff_ffff));
    assert_eq!(constants["MAX_CROSSINGS"], Value::Int(24));
    assert_eq!(constants["SHADOW_OFFSET"], Value::Float(1.5));
    let parsed = parse_constants("const A: f32 = 1e-6; const B = -(2u + 3u) * 4u; const C: u32 = 1u << 5u;").unwrap();
    assert_eq!(parsed["A"], Value::Float(1e-6f32 as f64));
    assert_eq!(parsed["B"], Value::Int(-20));
    assert_eq!(parsed["C"], Value::Int(32));
    let bindings = parse_bindings(&ray_caster_source(BrickFiltering::Hardware)).unwrap();
    assert_eq!(bindings.len(), 13, "{bindings:?}");
    let sampler = bindings.iter().find(|b| b.name == "brick_sampler").unwrap();
    assert_eq!((sampler.binding, sampler.kind.as_str()), (12, "sampler"));
    let pixels = bindings.iter().find(|b| b.name == "pixels").unwrap();
    assert_eq!(pixels.kind, "storage read_write");
}

#[test]
fn a_changed_constant_is_caught() {
    let source = ray_caster_source(BrickFiltering::Exact);
    let twins = rust_twins();
    for (original, altered) in [
        ("const SHADOW_CONE: f32 = 2.0;", "const SHADOW_CONE: f32 = 2.5;"),
        ("const RUNG_RATIO: f32 = 1.189207115;", "const RUNG_RATIO: f32 = 1.1892073;"),
        ("const PIXEL_MISSED: u32 = 2u;", "const PIXEL_MISSED: u32 = 3u;"),
        ("const STEPS_PER_OCTAVE: f32 = 4.0;", "const STEPS_PER_OCTAVE: f32 = 8.0;"),
        ("const REQUEST_DEFICIT_SHIFT: u32 = 8u;", "const REQUEST_DEFICIT_SHIFT: u32 = 16u;"),
        ("const MAX_SURFACES: u32 = 8u;", "const MAX_SURFACES: u32 = 9u;"),
    ] {
        assert!(source.contains(original), "{original}");
        let problems = check_constants(&source.replace(original, altered), &twins);
        assert!(!problems.is_empty(), "{altered} passed");
    }
    // One ulp is allowed, two are not.
    let one_ulp = format!("const RUNG_RATIO: f32 = {};", f32::from_bits((step_table::RUNG_RATIO as f32).to_bits() + 1));
    assert!(check_constants(&source.replace("const RUNG_RATIO: f32 = 1.189207115;", &one_ulp), &twins).is_empty());
    let two_ulps =
        format!("const RUNG_RATIO: f32 = {};", f32::from_bits((step_table::RUNG_RATIO as f32).to_bits() + 2));
    assert!(!check_constants(&source.replace("const RUNG_RATIO: f32 = 1.189207115;", &two_ulps), &twins).is_empty());
    // A new constant must be listed; a listed one must exist.
    let added = format!("{source}\nconst NEW_THRESHOLD: f32 = 0.5;\n");
    assert!(check_constants(&added, &twins).iter().any(|p| p.contains("NEW_THRESHOLD")));
    let mut stale = twins.clone();
    stale.push(("GONE", Value::Int(1)));
    assert!(check_constants(&source, &stale).iter().any(|p| p.contains("GONE")));
}

#[test]
fn a_changed_binding_is_caught() {
    let filtering = BrickFiltering::Exact;
    let source = ray_caster_source(filtering);
    let entries = layout_entries(filtering);
    let renumbered =
        source.replace("@binding(10) var<storage, read> surfaces", "@binding(13) var<storage, read> surfaces");
    assert!(!check_bindings(&renumbered, &entries, &BINDINGS).is_empty(), "a renumbered binding passed");
    let writable = source.replace("var<storage, read> ranges", "var<storage, read_write> ranges");
    assert!(!check_bindings(&writable, &entries, &BINDINGS).is_empty(), "a storage binding's access passed");
    let added = format!("{source}\n@group(0) @binding(13) var<storage, read> extra: array<u32>;\n");
    let problems = check_bindings(&added, &entries, &BINDINGS);
    assert!(problems.iter().any(|p| p.contains("extra") && p.contains("BINDINGS")), "{problems:?}");
    let mut table = BINDINGS.to_vec();
    table.retain(|(name, _)| *name != "blends");
    assert!(!check_bindings(&source, &entries, &table).is_empty(), "a binding missing from the table passed");
    let fewer: Vec<_> = entries.iter().filter(|e| e.binding != 6).cloned().collect();
    assert!(!check_bindings(&source, &fewer, &BINDINGS).is_empty(), "a binding missing from the layout passed");
    let wrong_texture = layout_entries(BrickFiltering::Hardware);
    assert!(!check_bindings(&source, &wrong_texture, &BINDINGS).is_empty(), "the other variant's layout passed");
}
