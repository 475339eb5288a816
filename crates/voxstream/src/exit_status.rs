//! The binary's exit codes (README "Exit codes"): 0 success, 1 error, 2 bad command line, 3 image incomplete.

use std::fmt;

/// Any error other than the ones below.
pub const FAILURE: u8 = 1;

/// The command line could not be parsed.
pub const USAGE: u8 = 2;

/// The outputs were written, but some bricks the store says exist could not be read: coarser data stands in.
pub const INCOMPLETE_IMAGE: u8 = 3;

/// The error `render` ends with when bricks failed: the image and stats are written, but not exact.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IncompleteImage {
    /// Bricks that could not be read (each reported once as a warning).
    pub failed_bricks: usize,
}

impl fmt::Display for IncompleteImage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the image is incomplete: {} brick{} could not be read (see the warnings); coarser data stands in",
            self.failed_bricks,
            if self.failed_bricks == 1 { "" } else { "s" }
        )
    }
}

impl std::error::Error for IncompleteImage {}

/// The exit code for an error a command returned.
pub fn exit_code(error: &anyhow::Error) -> u8 {
    if error.downcast_ref::<IncompleteImage>().is_some() {
        INCOMPLETE_IMAGE
    } else {
        FAILURE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn incomplete_images_have_their_own_code() {
        assert_eq!(exit_code(&anyhow::Error::new(IncompleteImage { failed_bricks: 2 })), INCOMPLETE_IMAGE);
        assert_eq!(exit_code(&anyhow::anyhow!("other")), FAILURE);
    }
}
