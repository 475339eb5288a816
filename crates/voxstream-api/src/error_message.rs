//! How an error reads to the user: its chain of contexts joined by ": " (as anyhow's `{:#}`), with every I/O error
//! said as a plain reason ("not found", "permission denied") and no " (os error N)" suffix, also where a library's
//! message embeds an I/O error's text.

use voxstream_store::error::describe_io;

/// The one line printed after "error: " for `error`.
pub fn user_message(error: &anyhow::Error) -> String {
    error
        .chain()
        .map(|cause| match cause.downcast_ref::<std::io::Error>() {
            Some(io) => describe_io(io),
            None => without_os_error_numbers(&cause.to_string()),
        })
        .collect::<Vec<_>>()
        .join(": ")
}

/// `text` without std's " (os error N)" suffixes, wherever they are.
fn without_os_error_numbers(text: &str) -> String {
    const MARK: &str = " (os error ";
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find(MARK) {
        let after = &rest[at + MARK.len()..];
        let digits = after.chars().take_while(char::is_ascii_digit).count();
        if digits > 0 && after[digits..].starts_with(')') {
            out.push_str(&rest[..at]);
            rest = &after[digits + 1..];
        } else {
            out.push_str(&rest[..at + MARK.len()]);
            rest = after;
        }
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;

    #[test]
    fn io_errors_read_as_plain_reasons() {
        let missing: anyhow::Result<()> = Err(std::io::Error::from_raw_os_error(2)).context("cannot read tf.json");
        assert_eq!(user_message(&missing.unwrap_err()), "cannot read tf.json: not found");
        let denied: anyhow::Result<()> = Err(std::io::Error::from_raw_os_error(13)).context("cannot create out.png");
        assert_eq!(user_message(&denied.unwrap_err()), "cannot create out.png: permission denied");
    }

    #[test]
    fn embedded_os_error_numbers_are_dropped() {
        let error = anyhow::anyhow!("a.ply: No such file or directory (os error 2); b: Is a directory (os error 21)");
        assert_eq!(user_message(&error), "a.ply: No such file or directory; b: Is a directory");
        let error = anyhow::anyhow!("value (os error x) stays");
        assert_eq!(user_message(&error), "value (os error x) stays");
    }
}
