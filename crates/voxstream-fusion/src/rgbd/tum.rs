//! Reading and writing RGB-D sequences in the layout of the TUM RGB-D benchmark (Sturm, Engelhard, Endres,
//! Burgard and Cremers, "A benchmark for the evaluation of RGB-D SLAM systems", IROS 2012), on which seed 004 §8.2
//! evaluates the fusion.
//!
//! A sequence is a folder holding `rgb/` and `depth/` PNGs, the lists `rgb.txt` and `depth.txt` (lines
//! `timestamp path`, `#` comments) and optionally `groundtruth.txt` (`timestamp tx ty tz qx qy qz qw`, camera to
//! world). Depth PNGs are 16-bit grayscale, metres = value / 5000, 0 = no measurement; colour PNGs are 8-bit RGB
//! (RGBA, gray and 16-bit colour are read too).
//!
//! Association follows the benchmark's `associate.py`: every (depth, colour) pair closer than 0.02 s in time is a
//! candidate, and the closest pairs are taken first, each frame used once; depth frames left without colour are
//! skipped. A frame's ground-truth pose is interpolated (translation linearly, rotation by slerp) between the two
//! ground-truth entries around its depth timestamp when both lie within 0.02 s of it, else the nearest entry within
//! 0.02 s is taken, else the frame has no pose.

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Component, Path, PathBuf};

use glam::{DQuat, DVec3};

use crate::camera::{Intrinsics, Pose};
use crate::frame::RgbdFrame;
use crate::FusionError;

/// The benchmark's depth scale: a 16-bit value of 5000 is one metre.
pub const DEPTH_SCALE: f64 = 5000.0;

/// Frames and poses further apart in time than this are not associated, seconds (`associate.py`'s default).
pub const MAX_TIME_DIFFERENCE: f64 = 0.02;

/// One associated frame of a dataset.
#[derive(Clone, Debug)]
struct Entry {
    timestamp: f64,
    depth: PathBuf,
    colour: PathBuf,
    pose: Option<Pose>,
}

/// A TUM RGB-D sequence opened for reading: its lists parsed and associated; images are read by [`TumDataset::frame`].
#[derive(Clone, Debug)]
pub struct TumDataset {
    dir: PathBuf,
    intrinsics: Intrinsics,
    entries: Vec<Entry>,
    ground_truth: bool,
    unmatched_depth: usize,
}

fn file_error(path: &Path, message: impl Into<String>) -> FusionError {
    FusionError::File { path: path.to_path_buf(), message: message.into() }
}

fn read_text(path: &Path, what: &str) -> Result<String, FusionError> {
    match std::fs::read_to_string(path) {
        Ok(text) => Ok(text),
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => Err(file_error(
            path,
            format!("missing: {what} (a TUM RGB-D folder holds rgb.txt, depth.txt, rgb/ and depth/; give that folder)"),
        )),
        Err(error) => Err(file_error(path, format!("cannot read: {error}"))),
    }
}

/// The non-comment lines of a list file with their 1-based line numbers, split at whitespace.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, line)| {
        let line = line.trim();
        (!line.is_empty() && !line.starts_with('#')).then(|| (i + 1, line.split_whitespace().collect()))
    })
}

fn parse_timestamp(path: &Path, line: usize, word: &str) -> Result<f64, FusionError> {
    match word.parse::<f64>() {
        Ok(t) if t.is_finite() => Ok(t),
        _ => {
            Err(file_error(path, format!("line {line}: `{word}` is not a timestamp (seconds): fix or remove the line")))
        }
    }
}

/// Parses `rgb.txt` or `depth.txt`: `(timestamp, path relative to the folder)`, sorted by time.
fn read_list(dir: &Path, name: &str) -> Result<Vec<(f64, PathBuf)>, FusionError> {
    let path = dir.join(name);
    let text = read_text(&path, &format!("the list of {} images", if name == "rgb.txt" { "colour" } else { "depth" }))?;
    let mut list = Vec::new();
    for (line, words) in data_lines(&text) {
        if words.len() != 2 {
            return Err(file_error(
                &path,
                format!(
                    "line {line}: expected `timestamp filename`, found {} fields: fix or remove the line",
                    words.len()
                ),
            ));
        }
        let timestamp = parse_timestamp(&path, line, words[0])?;
        let relative = PathBuf::from(words[1]);
        if relative.components().any(|c| !matches!(c, Component::Normal(_))) {
            return Err(file_error(
                &path,
                format!("line {line}: `{}` must be a path inside the folder (like rgb/0.000000.png)", words[1]),
            ));
        }
        list.push((timestamp, relative));
    }
    if list.is_empty() {
        return Err(file_error(&path, "lists no images: give a folder with a recorded sequence"));
    }
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(list)
}

/// Parses `groundtruth.txt`: `(timestamp, camera-to-world pose)`, sorted by time.
fn read_ground_truth(path: &Path) -> Result<Vec<(f64, DVec3, DQuat)>, FusionError> {
    let text = read_text(path, "ground truth")?;
    let mut poses = Vec::new();
    for (line, words) in data_lines(&text) {
        if words.len() != 8 {
            return Err(file_error(
                path,
                format!("line {line}: expected `timestamp tx ty tz qx qy qz qw`, found {} fields", words.len()),
            ));
        }
        let timestamp = parse_timestamp(path, line, words[0])?;
        let mut values = [0.0f64; 7];
        for (value, word) in values.iter_mut().zip(&words[1..]) {
            *value = match word.parse::<f64>() {
                Ok(v) if v.is_finite() => v,
                _ => return Err(file_error(path, format!("line {line}: `{word}` is not a number: fix the line"))),
            };
        }
        let q = DQuat::from_xyzw(values[3], values[4], values[5], values[6]);
        if q.length() <= 1e-6 {
            return Err(file_error(path, format!("line {line}: the rotation quaternion is zero: fix the line")));
        }
        poses.push((timestamp, DVec3::new(values[0], values[1], values[2]), q.normalize()));
    }
    poses.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(poses)
}

/// Indices of the entries of `sorted` within `MAX_TIME_DIFFERENCE` of `t`.
fn within(sorted: &[(f64, PathBuf)], t: f64) -> std::ops::Range<usize> {
    let start = sorted.partition_point(|e| e.0 < t - MAX_TIME_DIFFERENCE);
    let end = sorted.partition_point(|e| e.0 <= t + MAX_TIME_DIFFERENCE);
    start..end.max(start)
}

/// The pose at `t`: interpolated between the bracketing entries when both are within `MAX_TIME_DIFFERENCE`, else
/// the nearest within it.
fn pose_at(poses: &[(f64, DVec3, DQuat)], t: f64) -> Option<Pose> {
    let after = poses.partition_point(|p| p.0 < t);
    let before = after.checked_sub(1).map(|i| &poses[i]);
    let next = poses.get(after);
    let near = |p: &&(f64, DVec3, DQuat)| (p.0 - t).abs() <= MAX_TIME_DIFFERENCE;
    let to_pose = |p: DVec3, q: DQuat| Pose::from_rotation_translation(q, p);
    match (before.filter(near), next.filter(near)) {
        (Some(a), Some(b)) if b.0 > a.0 => {
            let s = (t - a.0) / (b.0 - a.0);
            Some(to_pose(a.1.lerp(b.1, s), a.2.slerp(b.2, s).normalize()))
        }
        (Some(a), Some(b)) => Some(to_pose(b.1, if (a.0 - t).abs() < (b.0 - t).abs() { a.2 } else { b.2 })),
        (Some(p), None) | (None, Some(p)) => Some(to_pose(p.1, p.2)),
        (None, None) => None,
    }
}

impl TumDataset {
    /// Opens the sequence in `dir`: parses `rgb.txt`, `depth.txt` and, if present, `groundtruth.txt`, and associates
    /// them (see the module's documentation). The intrinsics are [`Intrinsics::TUM_DEFAULT`] until
    /// [`TumDataset::with_intrinsics`] says otherwise.
    pub fn open(dir: &Path) -> Result<TumDataset, FusionError> {
        if !dir.is_dir() {
            let problem = if dir.exists() { "not a folder" } else { "does not exist" };
            return Err(file_error(
                dir,
                format!("{problem}: give the folder of a TUM RGB-D sequence (holding depth.txt)"),
            ));
        }
        let depth = read_list(dir, "depth.txt")?;
        let colour = read_list(dir, "rgb.txt")?;
        let truth_path = dir.join("groundtruth.txt");
        let truth = if truth_path.exists() { Some(read_ground_truth(&truth_path)?) } else { None };
        // associate.py: all candidate pairs, closest first, each frame used once.
        let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
        for (d, (t, _)) in depth.iter().enumerate() {
            for c in within(&colour, *t) {
                candidates.push(((colour[c].0 - t).abs(), d, c));
            }
        }
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut colour_of = vec![None; depth.len()];
        let mut colour_used = vec![false; colour.len()];
        for (_, d, c) in candidates {
            if colour_of[d].is_none() && !colour_used[c] {
                colour_of[d] = Some(c);
                colour_used[c] = true;
            }
        }
        let mut entries = Vec::with_capacity(depth.len());
        for ((timestamp, path), c) in depth.iter().zip(&colour_of) {
            let Some(c) = c else { continue };
            let pose = truth.as_deref().and_then(|poses| pose_at(poses, *timestamp));
            entries.push(Entry { timestamp: *timestamp, depth: path.clone(), colour: colour[*c].1.clone(), pose });
        }
        if entries.is_empty() {
            return Err(file_error(
                &dir.join("depth.txt"),
                format!(
                    "no depth frame has a colour frame within {MAX_TIME_DIFFERENCE} s in rgb.txt: check that the lists \
                     belong to the same recording"
                ),
            ));
        }
        let unmatched_depth = depth.len() - entries.len();
        Ok(TumDataset {
            dir: dir.to_path_buf(),
            intrinsics: Intrinsics::TUM_DEFAULT,
            entries,
            ground_truth: truth.is_some(),
            unmatched_depth,
        })
    }

    /// The same dataset read with other intrinsics (the freiburg1/2/3 calibrations, or a synthetic camera).
    pub fn with_intrinsics(mut self, intrinsics: Intrinsics) -> TumDataset {
        self.intrinsics = intrinsics;
        self
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Associated frames.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no frame is associated (never true for an opened dataset).
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The intrinsics images are read with.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// Whether the folder has `groundtruth.txt` (frames outside its time span still have no pose).
    pub fn has_ground_truth(&self) -> bool {
        self.ground_truth
    }

    /// Depth frames skipped because no colour frame was within 0.02 s.
    pub fn unmatched_depth_frames(&self) -> usize {
        self.unmatched_depth
    }

    /// The depth timestamp of frame `i`, seconds.
    pub fn timestamp(&self, i: usize) -> Option<f64> {
        self.entries.get(i).map(|e| e.timestamp)
    }

    /// The ground-truth pose of frame `i`, where known.
    pub fn ground_truth(&self, i: usize) -> Option<Pose> {
        self.entries.get(i).and_then(|e| e.pose)
    }

    /// Reads frame `i`: both PNGs, checked against the intrinsics before they are decoded.
    pub fn frame(&self, i: usize) -> Result<RgbdFrame, FusionError> {
        let Some(entry) = self.entries.get(i) else {
            return Err(FusionError::Dataset(format!(
                "frame {i} asked of {}, which has {} frames",
                self.dir.display(),
                self.entries.len()
            )));
        };
        let depth = read_depth_png(&self.dir.join(&entry.depth), &self.intrinsics)?;
        let colour = read_colour_png(&self.dir.join(&entry.colour), &self.intrinsics)?;
        Ok(RgbdFrame { timestamp: entry.timestamp, intrinsics: self.intrinsics, depth, colour, pose: entry.pose })
    }
}

/// What a PNG's header (its IHDR chunk, the first after the signature) says.
#[derive(Clone, Copy, Debug)]
struct PngHeader {
    width: u32,
    height: u32,
    bit_depth: u8,
    colour_type: u8,
}

/// Reads a PNG's first 26 bytes and checks its size against `intrinsics`; the decoder never sees a file whose
/// header claims another size, so a forged header cannot make it allocate.
fn open_png(path: &Path, intrinsics: &Intrinsics) -> Result<(PngHeader, Vec<u8>), FusionError> {
    let mut file = File::open(path)
        .map_err(|error| file_error(path, format!("cannot open: {error} (is the list pointing at the right file?)")))?;
    let mut head = [0u8; 26];
    file.read_exact(&mut head).map_err(|_| file_error(path, "too short to be a PNG: replace the file"))?;
    if head[..8] != [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A] || &head[12..16] != b"IHDR" {
        return Err(file_error(path, "not a PNG: the benchmark's images are PNG files"));
    }
    let word = |at: usize| u32::from_be_bytes([head[at], head[at + 1], head[at + 2], head[at + 3]]);
    let header = PngHeader { width: word(16), height: word(20), bit_depth: head[24], colour_type: head[25] };
    if header.width != intrinsics.width || header.height != intrinsics.height {
        return Err(file_error(
            path,
            format!(
                "the image is {}×{} but the intrinsics are {}×{}: give the sequence's intrinsics and image size \
                 (`fuse --intrinsics FX,FY,CX,CY,WIDTH,HEIGHT`)",
                header.width, header.height, intrinsics.width, intrinsics.height
            ),
        ));
    }
    let channels: u64 = match header.colour_type {
        0 | 3 => 1,
        2 => 3,
        4 => 2,
        6 => 4,
        other => return Err(file_error(path, format!("PNG colour type {other} does not exist: replace the file"))),
    };
    let mut bytes = head.to_vec();
    file.read_to_end(&mut bytes).map_err(|error| file_error(path, format!("cannot read: {error}")))?;
    // Deflate cannot compress more than about 1032 : 1, so a file far smaller than its image is truncated or its
    // header forged; refusing it keeps the decoder from allocating for the header's claim.
    let row = (u64::from(header.width) * channels * u64::from(header.bit_depth)).div_ceil(8) + 1;
    let raw = row * u64::from(header.height);
    if raw > bytes.len() as u64 * 1100 + 4096 {
        return Err(file_error(
            path,
            format!(
                "the header claims {}×{} pixels ({raw} bytes) but the file holds only {} bytes: it is truncated or \
                 damaged, replace it",
                header.width,
                header.height,
                bytes.len()
            ),
        ));
    }
    Ok((header, bytes))
}

/// Decodes an already size-checked PNG with the given transformations, the decoder's memory limited to what such
/// an image needs.
fn decode(
    path: &Path,
    bytes: &[u8],
    transformations: png::Transformations,
) -> Result<(png::ColorType, png::BitDepth, Vec<u8>), FusionError> {
    // At most 8 bytes a pixel (16-bit RGBA) and the decoder's own buffers; `open_png` bounded the pixels.
    let header_pixels = u32::from_be_bytes([bytes[16], bytes[17], bytes[18], bytes[19]]) as usize
        * u32::from_be_bytes([bytes[20], bytes[21], bytes[22], bytes[23]]) as usize;
    let limits = png::Limits { bytes: header_pixels.saturating_mul(16).saturating_add(1 << 20) };
    let mut decoder = png::Decoder::new_with_limits(bytes, limits);
    decoder.set_transformations(transformations);
    let mut reader = decoder.read_info().map_err(|error| file_error(path, format!("broken PNG: {error}")))?;
    let mut buffer = vec![0u8; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).map_err(|error| file_error(path, format!("broken PNG: {error}")))?;
    buffer.truncate(info.buffer_size());
    Ok((info.color_type, info.bit_depth, buffer))
}

/// Reads a 16-bit depth PNG as metres.
pub fn read_depth_png(path: &Path, intrinsics: &Intrinsics) -> Result<Vec<f32>, FusionError> {
    let (header, bytes) = open_png(path, intrinsics)?;
    if header.colour_type != 0 {
        return Err(file_error(
            path,
            "a depth image must be grayscale (PNG colour type 0): the benchmark stores depth as 16-bit gray",
        ));
    }
    if header.bit_depth != 16 {
        return Err(file_error(
            path,
            format!(
                "a {}-bit depth PNG: depth must be 16-bit grayscale (metres × 5000); an 8-bit depth image has lost \
                 its precision, convert the original data instead",
                header.bit_depth
            ),
        ));
    }
    let (_, _, data) = decode(path, &bytes, png::Transformations::IDENTITY)?;
    if data.len() != intrinsics.pixel_count() * 2 {
        return Err(file_error(path, "the decoded depth image has the wrong size: replace the file"));
    }
    Ok(data.chunks_exact(2).map(|b| (f64::from(u16::from_be_bytes([b[0], b[1]])) / DEPTH_SCALE) as f32).collect())
}

/// Reads a colour PNG (RGB, RGBA, gray or gray with alpha; 8 or 16 bits, or palette) as 8-bit RGB.
pub fn read_colour_png(path: &Path, intrinsics: &Intrinsics) -> Result<Vec<[u8; 3]>, FusionError> {
    let (_, bytes) = open_png(path, intrinsics)?;
    let (colour_type, bit_depth, data) =
        decode(path, &bytes, png::Transformations::EXPAND | png::Transformations::STRIP_16)?;
    if bit_depth != png::BitDepth::Eight {
        return Err(file_error(path, format!("unexpected {bit_depth:?} colour after expansion: save it as 8-bit RGB")));
    }
    let pixels = intrinsics.pixel_count();
    let channels = match colour_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Indexed => {
            return Err(file_error(path, "a palette PNG the decoder did not expand: save it as 8-bit RGB"))
        }
    };
    if data.len() != pixels * channels {
        return Err(file_error(path, "the decoded colour image has the wrong size: replace the file"));
    }
    Ok(data.chunks_exact(channels).map(|p| if channels >= 3 { [p[0], p[1], p[2]] } else { [p[0]; 3] }).collect())
}

/// Writes a sequence in the benchmark's layout (see the module's documentation), frame by frame.
pub struct TumWriter {
    dir: PathBuf,
    depth_list: BufWriter<File>,
    colour_list: BufWriter<File>,
    ground_truth: Option<BufWriter<File>>,
    last_name: Option<String>,
    frames: usize,
}

fn create_file(path: &Path) -> Result<BufWriter<File>, FusionError> {
    File::create(path).map(BufWriter::new).map_err(|error| file_error(path, format!("cannot create: {error}")))
}

fn write_to(path: &Path, file: &mut impl Write, text: &str) -> Result<(), FusionError> {
    file.write_all(text.as_bytes()).map_err(|error| file_error(path, format!("cannot write: {error}")))
}

impl TumWriter {
    /// Creates `dir` (and its `rgb/` and `depth/`), refusing a folder that exists and is not empty unless
    /// `overwrite`; overwriting replaces the lists and `groundtruth.txt` and the images of the same names, and leaves
    /// other files in the folder alone.
    pub fn create(dir: &Path, overwrite: bool) -> Result<TumWriter, FusionError> {
        if dir.exists() {
            if !dir.is_dir() {
                return Err(file_error(dir, "exists and is not a folder: give a new folder for the sequence"));
            }
            let mut contents =
                std::fs::read_dir(dir).map_err(|error| file_error(dir, format!("cannot list: {error}")))?;
            if contents.next().is_some() && !overwrite {
                return Err(file_error(dir, "exists and is not empty: give a new folder, or allow overwriting"));
            }
        }
        for sub in [dir.to_path_buf(), dir.join("rgb"), dir.join("depth")] {
            std::fs::create_dir_all(&sub).map_err(|error| file_error(&sub, format!("cannot create: {error}")))?;
        }
        let truth = dir.join("groundtruth.txt");
        if truth.exists() {
            std::fs::remove_file(&truth).map_err(|error| file_error(&truth, format!("cannot replace: {error}")))?;
        }
        let mut depth_list = create_file(&dir.join("depth.txt"))?;
        let mut colour_list = create_file(&dir.join("rgb.txt"))?;
        write_to(&dir.join("depth.txt"), &mut depth_list, "# depth maps\n# file: 'voxstream'\n# timestamp filename\n")?;
        write_to(
            &dir.join("rgb.txt"),
            &mut colour_list,
            "# color images\n# file: 'voxstream'\n# timestamp filename\n",
        )?;
        Ok(TumWriter {
            dir: dir.to_path_buf(),
            depth_list,
            colour_list,
            ground_truth: None,
            last_name: None,
            frames: 0,
        })
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Writes `frame`'s depth (metres × 5000 rounded to 16 bits; beyond 65535 / 5000 m, or not finite: 0, missing)
    /// and colour as `depth/<t>.png` and `rgb/<t>.png`, `<t>` its timestamp with 6 decimals, and lists them; its pose,
    /// if known, goes to `groundtruth.txt`. Timestamps must increase (by at least a microsecond).
    pub fn write_frame(&mut self, frame: &RgbdFrame) -> Result<(), FusionError> {
        let k = &frame.intrinsics;
        if frame.depth.len() != k.pixel_count() || frame.colour.len() != k.pixel_count() {
            return Err(FusionError::Dataset(format!(
                "frame at {:.6} s has {} depth and {} colour pixels, but its intrinsics are {}×{}",
                frame.timestamp,
                frame.depth.len(),
                frame.colour.len(),
                k.width,
                k.height
            )));
        }
        if !(frame.timestamp.is_finite() && frame.timestamp >= 0.0) {
            return Err(FusionError::Dataset(format!("frame timestamp {} must be finite and ≥ 0", frame.timestamp)));
        }
        let name = format!("{:.6}", frame.timestamp);
        if let Some(last) = &self.last_name {
            let previous: f64 = last.parse().unwrap_or(f64::NEG_INFINITY);
            if name.parse::<f64>().unwrap_or(f64::NEG_INFINITY) <= previous {
                return Err(FusionError::Dataset(format!(
                    "frame timestamp {name} does not follow the previous frame's {last}: timestamps must increase"
                )));
            }
        }
        let depth: Vec<u8> = frame
            .depth
            .iter()
            .flat_map(|&z| {
                let value = (f64::from(z) * DEPTH_SCALE).round();
                let value = if value.is_finite() && value > 0.0 && value <= 65535.0 { value as u16 } else { 0 };
                value.to_be_bytes()
            })
            .collect();
        let depth_name = format!("depth/{name}.png");
        let colour_name = format!("rgb/{name}.png");
        write_png(
            &self.dir.join(&depth_name),
            k.width,
            k.height,
            png::ColorType::Grayscale,
            png::BitDepth::Sixteen,
            &depth,
        )?;
        let colour: Vec<u8> = frame.colour.iter().flatten().copied().collect();
        write_png(&self.dir.join(&colour_name), k.width, k.height, png::ColorType::Rgb, png::BitDepth::Eight, &colour)?;
        write_to(&self.dir.join("depth.txt"), &mut self.depth_list, &format!("{name} {depth_name}\n"))?;
        write_to(&self.dir.join("rgb.txt"), &mut self.colour_list, &format!("{name} {colour_name}\n"))?;
        if let Some(pose) = frame.pose {
            let path = self.dir.join("groundtruth.txt");
            if self.ground_truth.is_none() {
                let mut file = create_file(&path)?;
                write_to(
                    &path,
                    &mut file,
                    "# ground truth trajectory\n# file: 'voxstream'\n# timestamp tx ty tz qx qy qz qw\n",
                )?;
                self.ground_truth = Some(file);
            }
            let t = pose.translation;
            let q = DQuat::from_mat3(&pose.matrix3).normalize();
            let line = format!("{name} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}\n", t.x, t.y, t.z, q.x, q.y, q.z, q.w);
            if let Some(file) = self.ground_truth.as_mut() {
                write_to(&path, file, &line)?;
            }
        }
        self.last_name = Some(name);
        self.frames += 1;
        Ok(())
    }

    /// Flushes the lists.
    pub fn finish(mut self) -> Result<(), FusionError> {
        let flush = |path: PathBuf, file: &mut BufWriter<File>| {
            file.flush().map_err(|error| file_error(&path, format!("cannot write: {error}")))
        };
        flush(self.dir.join("depth.txt"), &mut self.depth_list)?;
        flush(self.dir.join("rgb.txt"), &mut self.colour_list)?;
        if let Some(file) = self.ground_truth.as_mut() {
            flush(self.dir.join("groundtruth.txt"), file)?;
        }
        Ok(())
    }
}

fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    colour: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<(), FusionError> {
    let file = create_file(path)?;
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(colour);
    encoder.set_depth(depth);
    encoder.set_compression(png::Compression::Fast);
    let fail = |error: png::EncodingError| file_error(path, format!("cannot write: {error}"));
    let mut writer = encoder.write_header().map_err(fail)?;
    writer.write_image_data(data).map_err(fail)?;
    writer.finish().map_err(fail)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> Intrinsics {
        Intrinsics { width: 16, height: 12, fx: 13.0, fy: 13.0, cx: 7.5, cy: 5.5 }
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("voxstream-tum-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    fn frame(i: usize, pose: Option<Pose>) -> RgbdFrame {
        let k = small();
        let depth = (0..k.pixel_count())
            .map(|p| match p % 13 {
                0 => 0.0,
                1 => 20.0, // beyond 65535 / 5000 m: written as missing
                _ => 0.4 + (p * 7 + i) as f32 * 0.0123,
            })
            .collect();
        let colour = (0..k.pixel_count()).map(|p| [(p * 3 + i) as u8, (p * 5) as u8, (255 - p) as u8]).collect();
        RgbdFrame { timestamp: 1305031102.175304 + i as f64 / 30.0, intrinsics: k, depth, colour, pose }
    }

    fn pose(i: usize) -> Pose {
        let rotation = DQuat::from_euler(glam::EulerRot::XYZ, 0.1 * i as f64, -0.3, 0.7 + 0.05 * i as f64);
        Pose::from_rotation_translation(rotation, DVec3::new(1.0 + i as f64, -2.0, 0.5))
    }

    #[test]
    fn written_sequences_read_back() {
        let dir = scratch("round-trip");
        let frames: Vec<RgbdFrame> = (0..4).map(|i| frame(i, (i != 2).then(|| pose(i)))).collect();
        let mut writer = TumWriter::create(&dir, false).unwrap();
        for f in &frames {
            writer.write_frame(f).unwrap();
        }
        assert_eq!(writer.frames(), 4);
        writer.finish().unwrap();
        let dataset = TumDataset::open(&dir).unwrap().with_intrinsics(small());
        assert_eq!(dataset.len(), 4);
        assert!(dataset.has_ground_truth());
        for (i, written) in frames.iter().enumerate() {
            let read = dataset.frame(i).unwrap();
            assert!((read.timestamp - written.timestamp).abs() < 1e-6, "{} {}", read.timestamp, written.timestamp);
            assert_eq!(read.colour, written.colour, "colour is exact");
            for (r, w) in read.depth.iter().zip(&written.depth) {
                let expected = if *w > 65535.0 / 5000.0 { 0.0 } else { *w };
                assert!((r - expected).abs() < 2e-4, "depth {r} written as {w}");
            }
            match (read.pose, written.pose) {
                (Some(r), Some(w)) => {
                    assert!(r.abs_diff_eq(w, 1e-6), "pose {i}: {r:?} vs {w:?}");
                }
                // Frame 2 has no pose of its own: it is interpolated between frames 1 and 3 (1/30 s > 0.02 s away
                // from each, so nothing).
                (r, w) => assert_eq!((r.is_some(), w.is_some()), (false, false), "frame {i}"),
            }
        }
        assert!(dataset.frame(4).unwrap_err().to_string().contains("has 4 frames"));
        // An existing non-empty folder is refused unless overwriting.
        let refused = TumWriter::create(&dir, false).err().unwrap().to_string();
        assert!(refused.contains("not empty"), "{refused}");
        let mut again = TumWriter::create(&dir, true).unwrap();
        again.write_frame(&frame(0, None)).unwrap();
        assert!(again.write_frame(&frame(0, None)).is_err(), "timestamps must increase");
        again.finish().unwrap();
        let dataset = TumDataset::open(&dir).unwrap().with_intrinsics(small());
        assert_eq!(dataset.len(), 1);
        assert!(!dataset.has_ground_truth(), "the old ground truth is gone");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn association_and_interpolation_follow_the_benchmark() {
        let dir = scratch("associate");
        std::fs::create_dir_all(&dir).unwrap();
        // Depth at 1.00, 1.10, 1.20, 1.30; colour at 1.005, 1.011 (both near 1.00: the closer wins), 1.215, 1.60.
        std::fs::write(
            dir.join("depth.txt"),
            "# depth\n1.00 depth/a.png\n1.10 depth/b.png\n1.20 depth/c.png\n1.30 depth/d.png\n",
        )
        .unwrap();
        std::fs::write(dir.join("rgb.txt"), "1.011 rgb/y.png\n1.005 rgb/x.png\n1.215 rgb/z.png\n1.60 rgb/w.png\n")
            .unwrap();
        std::fs::write(
            dir.join("groundtruth.txt"),
            "# gt\n0.99 0 0 0 0 0 0 1\n1.01 2 0 0 0 0 0.7071067811865476 0.7071067811865476\n1.25 5 5 5 0 0 0 1\n",
        )
        .unwrap();
        let dataset = TumDataset::open(&dir).unwrap();
        assert_eq!(dataset.len(), 2);
        assert_eq!(dataset.unmatched_depth_frames(), 2);
        assert_eq!(dataset.entries[0].colour, PathBuf::from("rgb/x.png"));
        assert_eq!(dataset.entries[1].colour, PathBuf::from("rgb/z.png"));
        // Halfway between 0.99 and 1.01: x = 1, a rotation of 45° about z.
        let p = dataset.ground_truth(0).unwrap();
        assert!((p.translation - DVec3::new(1.0, 0.0, 0.0)).length() < 1e-12, "{p:?}");
        let expected = glam::DMat3::from_rotation_z(std::f64::consts::FRAC_PI_4);
        assert!(p.matrix3.abs_diff_eq(expected, 1e-12), "{p:?}");
        // 1.20: the nearest entry 1.25 is 0.05 s away: no pose.
        assert_eq!(dataset.ground_truth(1), None);
        // The images are missing: the error names the file.
        let missing = dataset.frame(0).unwrap_err().to_string();
        assert!(missing.contains("depth/a.png") && missing.contains("cannot open"), "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_lists_are_named_with_their_line() {
        let dir = scratch("bad-lists");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("rgb.txt"), "1.0 rgb/x.png\n").unwrap();
        let missing = TumDataset::open(&dir).unwrap_err().to_string();
        assert!(missing.contains("depth.txt") && missing.contains("missing"), "{missing}");
        std::fs::write(dir.join("depth.txt"), "# header\n1.0 depth/a.png\n\n1.1depth/b.png\n").unwrap();
        let malformed = TumDataset::open(&dir).unwrap_err().to_string();
        assert!(malformed.contains("depth.txt: line 4: expected `timestamp filename`"), "{malformed}");
        std::fs::write(dir.join("depth.txt"), "1.0 depth/a.png\nnan depth/b.png\n").unwrap();
        let nan = TumDataset::open(&dir).unwrap_err().to_string();
        assert!(nan.contains("line 2: `nan` is not a timestamp"), "{nan}");
        std::fs::write(dir.join("depth.txt"), "1.0 ../../etc/passwd\n").unwrap();
        let outside = TumDataset::open(&dir).unwrap_err().to_string();
        assert!(outside.contains("inside the folder"), "{outside}");
        std::fs::write(dir.join("depth.txt"), "1.0 depth/a.png\n").unwrap();
        std::fs::write(dir.join("groundtruth.txt"), "1.0 1 2 3 0 0 0\n").unwrap();
        let truth = TumDataset::open(&dir).unwrap_err().to_string();
        assert!(truth.contains("groundtruth.txt: line 1: expected `timestamp tx ty tz qx qy qz qw`"), "{truth}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_images_are_refused_before_decoding() {
        let dir = scratch("bad-images");
        let mut writer = TumWriter::create(&dir, false).unwrap();
        writer.write_frame(&frame(0, None)).unwrap();
        writer.finish().unwrap();
        let depth_path = dir.join(format!("depth/{:.6}.png", frame(0, None).timestamp));
        // Other intrinsics: the size disagrees.
        let wrong = TumDataset::open(&dir).unwrap().frame(0).unwrap_err().to_string();
        assert!(wrong.contains("16×12 but the intrinsics are 640×480"), "{wrong}");
        let dataset = TumDataset::open(&dir).unwrap().with_intrinsics(small());
        assert!(dataset.frame(0).is_ok());
        // An 8-bit depth image.
        write_png(&depth_path, 16, 12, png::ColorType::Grayscale, png::BitDepth::Eight, &[7u8; 16 * 12]).unwrap();
        let eight = dataset.frame(0).unwrap_err().to_string();
        assert!(eight.contains("8-bit depth PNG") && eight.contains(".png"), "{eight}");
        // A header claiming 100000 × 100000 (10¹⁰ pixels, 20 GB of 16-bit depth): refused for its size, and, with
        // intrinsics to match, because the file is far too small to hold it, before the decoder allocates.
        write_png(&depth_path, 16, 12, png::ColorType::Grayscale, png::BitDepth::Sixteen, &[7u8; 16 * 12 * 2]).unwrap();
        let mut bytes = std::fs::read(&depth_path).unwrap();
        bytes[16..20].copy_from_slice(&100_000u32.to_be_bytes());
        bytes[20..24].copy_from_slice(&100_000u32.to_be_bytes());
        std::fs::write(&depth_path, &bytes).unwrap();
        let forged = dataset.frame(0).unwrap_err().to_string();
        assert!(forged.contains("100000×100000 but the intrinsics are 16×12"), "{forged}");
        let huge = Intrinsics { width: 100_000, height: 100_000, ..small() };
        let started = std::time::Instant::now();
        let limited = read_depth_png(&depth_path, &huge).unwrap_err().to_string();
        assert!(limited.contains("claims 100000×100000 pixels") && limited.contains("truncated"), "{limited}");
        assert!(started.elapsed().as_secs_f64() < 1.0, "refused at once");
        // Not a PNG at all.
        std::fs::write(&depth_path, b"P5 16 12 65535 and some more bytes").unwrap();
        assert!(dataset.frame(0).unwrap_err().to_string().contains("not a PNG"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn colour_images_of_other_kinds_are_read() {
        let dir = scratch("colour-kinds");
        std::fs::create_dir_all(&dir).unwrap();
        let k = small();
        let path = dir.join("c.png");
        let rgba: Vec<u8> = (0..k.pixel_count() * 4).map(|i| i as u8).collect();
        write_png(&path, 16, 12, png::ColorType::Rgba, png::BitDepth::Eight, &rgba).unwrap();
        let read = read_colour_png(&path, &k).unwrap();
        assert_eq!(read[1], [4, 5, 6]);
        let gray: Vec<u8> = (0..k.pixel_count()).map(|i| i as u8).collect();
        write_png(&path, 16, 12, png::ColorType::Grayscale, png::BitDepth::Eight, &gray).unwrap();
        assert_eq!(read_colour_png(&path, &k).unwrap()[9], [9, 9, 9]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
