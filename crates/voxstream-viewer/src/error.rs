//! The viewer's errors.

/// What can keep the viewer from running, or end it with a failure.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// No display to open a window on.
    #[error("no display to open a window on: set DISPLAY (X11) or run under a virtual X server (xvfb-run -a voxstream view …)")]
    NoDisplay,
    /// The window could not be opened.
    #[error("cannot open the window: {0} (the viewer needs OpenGL 2+ through X11; on a machine without a GPU, Mesa's llvmpipe works)")]
    Window(String),
    /// The render thread could not start.
    #[error("cannot start the render thread: {0}")]
    Thread(#[from] std::io::Error),
    /// A script is malformed, or one of its commands failed.
    #[error("{0}")]
    Script(String),
}
