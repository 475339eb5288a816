//! `render --video`: a camera path's frames encoded as a movie by an `ffmpeg` process, fed raw RGB frames on its
//! standard input as they are rendered (the way matplotlib's and imageio's writers use it).
//!
//! Why a process rather than a crate: no pure-Rust H.264 or VP9 encoder is maintained, and the crates that bind
//! libavcodec need its headers and a matching version at build time; Debian's `ffmpeg` (or any other, named by
//! `VOXSTREAM_FFMPEG`) is found at run time, and only `--video` needs it. The movie is written to a temporary file
//! beside the output and renamed once ffmpeg has finished, so an interrupted or failed run leaves no half-written
//! movie under the final name.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

use anyhow::{bail, Context, Result};
use voxstream_render::Image;

use voxstream_engine::{output_target, temporary_path, OutputTarget};

use crate::output_file::{check_output, write_output};

/// The environment variable naming the ffmpeg to use (default: `ffmpeg` on `PATH`).
pub const FFMPEG_VARIABLE: &str = "VOXSTREAM_FFMPEG";

/// The containers `--video` writes, by extension: ffmpeg's name for it and the encoder arguments.
fn codec_arguments(path: &Path) -> Result<(&'static str, &'static [&'static str])> {
    const H264: &[&str] =
        &["-c:v", "libx264", "-preset", "medium", "-crf", "18", "-pix_fmt", "yuv420p", "-movflags", "+faststart"];
    const VP9: &[&str] = &["-c:v", "libvpx-vp9", "-crf", "30", "-b:v", "0", "-pix_fmt", "yuv420p"];
    let extension = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    Ok(match extension.as_deref() {
        Some("mp4") => ("mp4", H264),
        Some("mov") => ("mov", H264),
        Some("mkv") => ("matroska", H264),
        Some("webm") => ("webm", VP9),
        _ => bail!("--video {}: name a .mp4, .mov, .mkv (H.264) or .webm (VP9) file", path.display()),
    })
}

/// The ffmpeg program: `VOXSTREAM_FFMPEG`, else `ffmpeg`.
pub fn ffmpeg_program() -> PathBuf {
    std::env::var_os(FFMPEG_VARIABLE).map(PathBuf::from).unwrap_or_else(|| PathBuf::from("ffmpeg"))
}

/// Checks before any rendering that `path` is a movie ffmpeg can write and that ffmpeg runs.
pub fn check_video(path: &Path) -> Result<()> {
    codec_arguments(path)?;
    check_output(path, "--video")?;
    let program = ffmpeg_program();
    let runs = Command::new(&program)
        .arg("-version")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|status| status.success());
    if !runs {
        bail!(
            "--video needs ffmpeg, and `{}` could not be run: install it (Debian/Ubuntu: apt-get install ffmpeg; \
             or pip install imageio-ffmpeg and set {FFMPEG_VARIABLE} to its binary), or write PNG frames with --out \
             instead",
            program.display()
        );
    }
    Ok(())
}

/// A movie being written: frames go to ffmpeg's standard input.
pub struct VideoWriter {
    child: Child,
    stdin: Option<ChildStdin>,
    temporary: PathBuf,
    path: PathBuf,
    width: u32,
    height: u32,
    frames: usize,
}

impl VideoWriter {
    /// Starts ffmpeg writing `path` from `width × height` RGB frames at `fps` frames a second.
    pub fn start(path: &Path, width: u32, height: u32, fps: f64) -> Result<VideoWriter> {
        let (container, codec) = codec_arguments(path)?;
        // Encoded beside the file it replaces (then renamed), or in the temporary folder for a FIFO or a device
        // (then copied into it).
        let temporary = match output_target(path)? {
            OutputTarget::Replace(target) => temporary_path(&target),
            OutputTarget::Stream => std::env::temp_dir()
                .join(temporary_path(Path::new("voxstream-video")).file_name().expect("a file name").to_os_string()),
        };
        let mut command = Command::new(ffmpeg_program());
        command
            .args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y"])
            .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-s", &format!("{width}x{height}")])
            .args(["-framerate", &format!("{fps}"), "-i", "pipe:0"])
            // 4:2:0 chroma needs even sizes: an odd edge is padded by one pixel of the last row or column.
            .args(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"])
            .args(codec)
            .args(["-f", container])
            .arg(&temporary)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = command.spawn().with_context(|| format!("cannot start {}", ffmpeg_program().display()))?;
        let stdin = child.stdin.take();
        Ok(VideoWriter { child, stdin, temporary, path: path.to_path_buf(), width, height, frames: 0 })
    }

    /// Appends one frame.
    pub fn push(&mut self, image: &Image) -> Result<()> {
        if image.width != self.width || image.height != self.height {
            bail!("a {}x{} frame in a {}x{} movie", image.width, image.height, self.width, self.height);
        }
        let Some(stdin) = self.stdin.as_mut() else { bail!("the movie was already finished") };
        if let Err(error) = stdin.write_all(&image.to_rgb8()) {
            // ffmpeg has stopped: its own message says why.
            let stdin = self.stdin.take();
            drop(stdin);
            let reason = self.ffmpeg_error();
            bail!("ffmpeg stopped while writing {} ({error}){reason}", self.path.display());
        }
        self.frames += 1;
        Ok(())
    }

    /// Waits for ffmpeg to finish and moves the movie to its name; returns the frames written.
    pub fn finish(mut self) -> Result<usize> {
        drop(self.stdin.take());
        let status = self.child.wait().context("waiting for ffmpeg")?;
        if !status.success() {
            let reason = self.ffmpeg_error();
            bail!("ffmpeg could not write {} ({status}){reason}", self.path.display());
        }
        match output_target(&self.path)? {
            OutputTarget::Replace(target) => std::fs::rename(&self.temporary, &target)
                .with_context(|| format!("cannot move the movie to {}", self.path.display()))?,
            OutputTarget::Stream => {
                let mut movie = std::fs::File::open(&self.temporary).context("reading back the encoded movie")?;
                write_output(&self.path, |file| {
                    std::io::copy(&mut movie, file).with_context(|| format!("cannot write {}", self.path.display()))?;
                    Ok(())
                })?;
            }
        }
        Ok(self.frames)
    }

    /// ffmpeg's last message line, after waiting for it to exit.
    fn ffmpeg_error(&mut self) -> String {
        let _ = self.child.wait();
        let mut text = String::new();
        if let Some(mut stderr) = self.child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut stderr, &mut text);
        }
        text.lines().rev().find(|l| !l.trim().is_empty()).map(|l| format!(": {}", l.trim())).unwrap_or_default()
    }
}

impl Drop for VideoWriter {
    /// An unfinished movie (an error or an interrupt on the way) is not left behind.
    fn drop(&mut self) {
        if self.stdin.take().is_some() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        let _ = std::fs::remove_file(&self.temporary);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn containers_are_known_by_extension() {
        assert!(codec_arguments(Path::new("a.mp4")).unwrap().1.contains(&"libx264"));
        assert_eq!(codec_arguments(Path::new("a.mkv")).unwrap().0, "matroska");
        assert!(codec_arguments(Path::new("a.WEBM")).unwrap().1.contains(&"libvpx-vp9"));
        let error = codec_arguments(Path::new("a.avi")).unwrap_err().to_string();
        assert!(error.contains(".mp4") && error.contains("a.avi"), "{error}");
    }
}
