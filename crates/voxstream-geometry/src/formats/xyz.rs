//! Particles as columns of text (`.xyz`, `.csv`, `.txt`): one particle a line, `x y z [h] [value]`, separated by
//! blanks or by commas.
//!
//! `#` starts a comment (to the end of the line); blank lines are skipped. If the first line that is not a comment
//! is not all numbers, it names the columns: `x`, `y` and `z` (required), a smoothing length (`h`, `hsml`, `radius`,
//! `smoothing_length`), a mass (`mass`, `m`), and the first other column becomes the scalar attribute under its
//! name; further columns are ignored (names in any letter case, CSV quotes removed). Without such a header, 3
//! columns are positions, a 4th the smoothing length and a 5th a scalar named `value`. Every line must have as many
//! columns as the first; in a line with commas, an empty field is an error.
//!
//! Not read: the chemists' XYZ format (an atom count, a comment line, then `element x y z`), which is recognised
//! and refused with that explanation; quoted fields containing commas.

use std::path::Path;

use crate::error::GeometryError;
use crate::particles::RawParticles;

/// What a named column or array holds (shared with the VTK readers).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ColumnRole {
    /// A smoothing length or radius.
    Smoothing,
    /// A mass.
    Mass,
    /// Anything else: a candidate for the scalar attribute.
    Value,
}

/// The role of a column or array named `name` (letter case ignored).
pub(super) fn column_role(name: &str) -> ColumnRole {
    match name.trim().to_ascii_lowercase().as_str() {
        "h" | "hsml" | "radius" | "smoothing_length" | "smoothinglength" => ColumnRole::Smoothing,
        "m" | "mass" => ColumnRole::Mass,
        _ => ColumnRole::Value,
    }
}

/// Which column holds what.
struct Layout {
    columns: usize,
    position: [usize; 3],
    smoothing: Option<usize>,
    mass: Option<usize>,
    value: Option<(usize, String)>,
}

impl Layout {
    fn unnamed(columns: usize) -> Option<Layout> {
        if !(3..=5).contains(&columns) {
            return None;
        }
        Some(Layout {
            columns,
            position: [0, 1, 2],
            smoothing: (columns >= 4).then_some(3),
            mass: None,
            value: (columns == 5).then(|| (4, "value".to_string())),
        })
    }

    fn named(names: &[&str]) -> Result<Layout, String> {
        let mut position = [None; 3];
        let (mut smoothing, mut mass, mut value) = (None, None, None);
        for (column, raw) in names.iter().enumerate() {
            let name = raw.trim().trim_matches('"').trim_matches('\'').trim();
            let axis = match name.to_ascii_lowercase().as_str() {
                "x" => Some(0),
                "y" => Some(1),
                "z" => Some(2),
                _ => None,
            };
            if let Some(axis) = axis {
                if position[axis].is_some() {
                    return Err(format!("the header names column {name} twice"));
                }
                position[axis] = Some(column);
                continue;
            }
            match column_role(name) {
                ColumnRole::Smoothing if smoothing.is_none() => smoothing = Some(column),
                ColumnRole::Mass if mass.is_none() => mass = Some(column),
                ColumnRole::Value if value.is_none() => value = Some((column, name.to_string())),
                _ => {}
            }
        }
        let [Some(x), Some(y), Some(z)] = position else {
            let missing: Vec<&str> =
                ["x", "y", "z"].iter().zip(position).filter(|(_, c)| c.is_none()).map(|(n, _)| *n).collect();
            return Err(format!(
                "the header line ({}) has no column named {}: name the position columns x, y and z",
                names.join(" "),
                missing.join(", ")
            ));
        };
        Ok(Layout { columns: names.len(), position: [x, y, z], smoothing, mass, value })
    }
}

/// The fields of a line with its comment removed: split at commas if it has any, otherwise at blanks.
fn fields(line: &str) -> Vec<&str> {
    if line.contains(',') {
        line.split(',').map(str::trim).collect()
    } else {
        line.split_whitespace().collect()
    }
}

/// Parses columns of text.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawParticles, GeometryError> {
    let mut lines = Lines::default();
    for (line, number) in bytes.split(|&b| b == b'\n').zip(1u64..) {
        lines.read(line, number, path)?;
    }
    Ok(lines.raw)
}

/// The reading state: the columns' layout once the first line has given it, and the particles read since the last
/// [`Lines::take`].
#[derive(Default)]
struct Lines {
    layout: Option<Layout>,
    first_line: u64,
    raw: RawParticles,
}

impl Lines {
    /// Reads line `number` (without its `\n`).
    fn read(&mut self, line: &[u8], number: u64, path: &Path) -> Result<(), GeometryError> {
        let bad = |message: String| GeometryError::format(path, Some(number), message);
        let line = std::str::from_utf8(line).map_err(|_| bad("not text (invalid UTF-8)".into()))?;
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            return Ok(());
        }
        let fields = fields(line);
        if let Some(empty) = fields.iter().position(|f| f.is_empty()) {
            return Err(bad(format!("field {} is empty", empty + 1)));
        }
        let first_line = &mut self.first_line;
        let layout = match &mut self.layout {
            Some(layout) => layout,
            None => {
                *first_line = number;
                let numeric = fields.iter().all(|f| f.parse::<f64>().is_ok());
                if !numeric {
                    self.layout = Some(Layout::named(&fields).map_err(bad)?);
                    return Ok(());
                }
                if let [count] = fields.as_slice() {
                    if count.parse::<u64>().is_ok() {
                        return Err(bad(format!(
                            "a single number ({count}): this looks like a chemists' XYZ file (atom count, comment, \
                             element x y z), which is not read; write the columns x y z [h] [value] instead"
                        )));
                    }
                }
                self.layout.insert(Layout::unnamed(fields.len()).ok_or_else(|| {
                    bad(format!(
                        "{} columns: without a header line naming them, a line holds 3 to 5 (x y z [h] [value])",
                        fields.len()
                    ))
                })?)
            }
        };
        let first_line = self.first_line;
        if fields.len() != layout.columns {
            return Err(bad(format!(
                "expected {} columns (as on line {first_line}), found {}",
                layout.columns,
                fields.len()
            )));
        }
        let number_at = |column: usize| -> Result<f64, GeometryError> {
            let text = fields.get(column).copied().unwrap_or("");
            text.parse::<f64>().map_err(|_| bad(format!("column {}: '{text}' is not a number", column + 1)))
        };
        let raw = &mut self.raw;
        let [x, y, z] = layout.position;
        raw.positions.push([number_at(x)?, number_at(y)?, number_at(z)?]);
        if let Some(c) = layout.smoothing {
            raw.smoothing.push(number_at(c)? as f32);
        }
        if let Some(c) = layout.mass {
            raw.masses.push(number_at(c)? as f32);
        }
        if let Some((c, name)) = &layout.value {
            raw.values.push(number_at(*c)? as f32);
            if raw.value_name.is_empty() {
                raw.value_name.clone_from(name);
            }
        }
        Ok(())
    }
}

/// The longest line [`TextPointStream`] reads (a file without line breaks is not columns of text).
const STREAM_LINE_BYTES: u64 = 1 << 20;

/// Particles a [`TextPointStream`] chunk holds.
const STREAM_CHUNK_PARTICLES: usize = 1 << 16;

/// Columns of text read a line at a time, for particle sets larger than memory: each pass reads the file again and
/// hands on the particles in chunks, with the errors [`parse`] gives (file, line, problem). Not compressed files.
#[derive(Clone, Debug)]
pub struct TextPointStream {
    path: std::path::PathBuf,
    /// Whether the lines carry a smoothing length, a mass and a value (from the first line).
    columns: [bool; 3],
    value_name: String,
}

impl TextPointStream {
    /// Opens `path` and reads up to its first particle, for the columns' layout.
    pub fn open(path: &Path) -> Result<TextPointStream, GeometryError> {
        if path.to_string_lossy().to_lowercase().ends_with(".gz") {
            return Err(GeometryError::Unsupported {
                path: path.to_path_buf(),
                message: "a compressed file is read whole; decompress it to read it out of core".into(),
            });
        }
        let mut columns = None;
        let mut stream = TextPointStream { path: path.to_path_buf(), columns: [false; 3], value_name: String::new() };
        let mut value_name = String::new();
        stream.pass(&mut |_, _, lines| {
            if let Some(layout) = &lines.layout {
                columns = Some([layout.smoothing.is_some(), layout.mass.is_some(), layout.value.is_some()]);
                value_name = layout.value.as_ref().map(|(_, name)| name.clone()).unwrap_or_default();
            }
            Ok(columns.is_none())
        })?;
        stream.value_name = value_name;
        stream.columns = columns.ok_or_else(|| GeometryError::Invalid {
            message: format!("{}: the file holds no particles", path.display()),
        })?;
        Ok(stream)
    }

    /// Whether the lines carry a smoothing length, a mass and a value.
    pub fn columns(&self) -> [bool; 3] {
        self.columns
    }

    /// The value column's name (`""` if none).
    pub fn value_name(&self) -> &str {
        &self.value_name
    }

    /// Reads the file's lines, calling `after` after each (with the index of the first particle not yet handed on and
    /// the state) until it returns false or the file ends.
    fn pass(
        &self,
        after: &mut dyn FnMut(bool, u64, &mut Lines) -> Result<bool, GeometryError>,
    ) -> Result<(), GeometryError> {
        use std::io::BufRead;
        let io = |error| GeometryError::Io { path: self.path.clone(), error };
        let file = std::fs::File::open(&self.path).map_err(io)?;
        let mut reader = std::io::BufReader::with_capacity(1 << 20, file);
        let mut lines = Lines::default();
        let mut line = Vec::new();
        let mut handed = 0u64;
        for number in 1u64.. {
            line.clear();
            let read =
                std::io::Read::take(&mut reader, STREAM_LINE_BYTES + 1).read_until(b'\n', &mut line).map_err(io)?;
            let end = read == 0;
            if !end {
                if line.last() == Some(&b'\n') {
                    line.pop();
                } else if line.len() as u64 > STREAM_LINE_BYTES {
                    return Err(GeometryError::format(
                        &self.path,
                        Some(number),
                        format!("a line longer than {STREAM_LINE_BYTES} bytes: not columns of text"),
                    ));
                }
                lines.read(&line, number, &self.path)?;
            }
            let before = lines.raw.positions.len() as u64;
            if !after(end, handed, &mut lines)? || end {
                break;
            }
            handed += before - lines.raw.positions.len() as u64;
        }
        Ok(())
    }

    /// Calls `f` with consecutive runs of the particles, each with the index of its first, in file order; stops at
    /// the first error, from the file or from `f`.
    pub fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        self.pass(&mut |end, first, lines| {
            let raw = &mut lines.raw;
            if raw.positions.len() >= STREAM_CHUNK_PARTICLES || (end && !raw.positions.is_empty()) {
                f(first, raw)?;
                raw.positions.clear();
                raw.smoothing.clear();
                raw.masses.clear();
                raw.values.clear();
            }
            Ok(true)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> Result<RawParticles, GeometryError> {
        parse(text.as_bytes(), Path::new("p.xyz"))
    }

    fn error(text: &str) -> String {
        parse_str(text).unwrap_err().to_string()
    }

    #[test]
    fn three_four_and_five_columns_without_header() {
        let p = parse_str("# particles\n0 0 0\n1 2 3 # the second\n\n").unwrap();
        assert_eq!(p.positions, vec![[0.0; 3], [1.0, 2.0, 3.0]]);
        assert!(p.smoothing.is_empty() && p.masses.is_empty() && p.values.is_empty());
        let p = parse_str("0 0 0 0.5\n1 1 1 0.25\n").unwrap();
        assert_eq!(p.smoothing, vec![0.5, 0.25]);
        let p = parse_str("0\t0 0 0.5 7\r\n1 1 1 0.25 -1e3\r\n").unwrap();
        assert_eq!(p.smoothing, vec![0.5, 0.25]);
        assert_eq!(p.values, vec![7.0, -1000.0]);
        assert_eq!(p.value_name, "value");
    }

    #[test]
    fn commas() {
        let p = parse_str("1.5, 2, 3\n4,5,6\n").unwrap();
        assert_eq!(p.positions, vec![[1.5, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    }

    #[test]
    fn header_names_the_columns() {
        let p = parse_str("# sph\nid,\"X\",y,z,Mass,hsml,temperature\n1,0,0,0,2,0.1,300\n2,1,1,1,3,0.2,400\n").unwrap();
        assert_eq!(p.positions, vec![[0.0; 3], [1.0; 3]]);
        assert_eq!(p.masses, vec![2.0, 3.0]);
        assert_eq!(p.smoothing, vec![0.1, 0.2]);
        // The first other column is the attribute.
        assert_eq!(p.values, vec![1.0, 2.0]);
        assert_eq!(p.value_name, "id");
        let p = parse_str("z y x radius\n3 2 1 0.5\n").unwrap();
        assert_eq!(p.positions, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(p.smoothing, vec![0.5]);
        assert!(p.values.is_empty());
    }

    #[test]
    fn errors_name_the_line_and_the_problem() {
        let e = error("0 0 0\n1 1 1\n\n# c\n2 2\n");
        assert_eq!(e, "p.xyz line 5: expected 3 columns (as on line 1), found 2");
        assert_eq!(
            error("0 0\n"),
            "p.xyz line 1: 2 columns: without a header line naming them, a line holds 3 to 5 (x y z [h] [value])"
        );
        assert_eq!(error("0 0 0\n0 a 0\n"), "p.xyz line 2: column 2: 'a' is not a number");
        assert_eq!(error("1,,2\n"), "p.xyz line 1: field 2 is empty");
        assert!(error("x y h\n0 0 0\n").contains("line 1: the header line (x y h) has no column named z"));
        assert!(error("x x y z\n").contains("names column x twice"));
        assert!(error("2\nwater\nO 0 0 0\n").contains("chemists' XYZ"));
        let e = parse(b"0 0 0\n0 0 \xff\n", Path::new("p.xyz")).unwrap_err().to_string();
        assert_eq!(e, "p.xyz line 2: not text (invalid UTF-8)");
        assert_eq!(parse_str("# nothing\n").unwrap(), RawParticles::default());
    }

    fn stream_file(name: &str, text: &[u8]) -> std::path::PathBuf {
        let path = std::env::temp_dir().join(format!("voxstream-text-stream-{}-{name}", std::process::id()));
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn a_text_stream_reads_what_parse_reads_in_chunks() {
        let mut text = String::from("# made by a test\r\nX, Y, Z, hsml, Temperature, mass\r\n\r\n");
        for i in 0..150_000 {
            text.push_str(&format!(
                "{}, {}, {}, 0.5, {}, 2 # particle {i}\r\n",
                i % 97,
                i % 89,
                i % 83,
                i as f64 * 0.5
            ));
        }
        let path = stream_file("points.csv", text.as_bytes());
        let stream = TextPointStream::open(&path).unwrap();
        assert_eq!(stream.columns(), [true, true, true]);
        assert_eq!(stream.value_name(), "Temperature");
        let mut all = RawParticles { value_name: "Temperature".into(), ..RawParticles::default() };
        let mut runs = 0;
        stream
            .for_each_chunk(&mut |first, run| {
                assert_eq!(first, all.positions.len() as u64);
                runs += 1;
                all.positions.extend(&run.positions);
                all.smoothing.extend(&run.smoothing);
                all.masses.extend(&run.masses);
                all.values.extend(&run.values);
                Ok(())
            })
            .unwrap();
        assert_eq!(runs, 3, "150,000 particles in runs of 65,536");
        assert_eq!(all, parse(text.as_bytes(), &path).unwrap());
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn a_text_stream_names_what_it_cannot_read() {
        let failure = |name: &str, text: &[u8]| {
            let path = stream_file(name, text);
            let error = TextPointStream::open(&path)
                .and_then(|stream| stream.for_each_chunk(&mut |_, _| Ok(())))
                .unwrap_err()
                .to_string();
            std::fs::remove_file(&path).ok();
            error
        };
        let bad = failure("bad.xyz", b"0 0 0\n1 1 1\n1 x 1\n");
        assert!(bad.ends_with("bad.xyz line 3: column 2: 'x' is not a number"), "{bad}");
        let long = failure("long.txt", &vec![b'1'; (STREAM_LINE_BYTES + 10) as usize]);
        assert!(long.contains("line 1: a line longer than 1048576 bytes"), "{long}");
        let empty = failure("empty.xyz", b"# nothing\n\n");
        assert!(empty.contains("the file holds no particles"), "{empty}");
        let compressed = failure("points.xyz.gz", b"0 0 0\n");
        assert!(compressed.contains("decompress it to read it out of core"), "{compressed}");
    }
}
