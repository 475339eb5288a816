//! An I/O error as a user reads it: "not found", "permission denied", … without std's " (os error N)" suffix. Shared
//! by every crate that names a file it could not read (the store's errors, JSON inputs, the CLI's messages).

/// `error` as a plain reason.
pub fn describe_io(error: &std::io::Error) -> String {
    use std::io::ErrorKind;
    match error.kind() {
        ErrorKind::NotFound => "not found".into(),
        ErrorKind::PermissionDenied => "permission denied".into(),
        ErrorKind::AlreadyExists => "already exists".into(),
        ErrorKind::UnexpectedEof => "ends too early (truncated)".into(),
        _ => {
            let text = error.to_string();
            // std appends " (os error N)" to OS errors: the number says nothing more to a user.
            match text.find(" (os error ") {
                Some(at) => text[..at].to_string(),
                None => text,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_are_plain_and_carry_no_os_numbers() {
        assert_eq!(describe_io(&std::io::Error::from_raw_os_error(2)), "not found");
        assert_eq!(describe_io(&std::io::Error::from_raw_os_error(20)), "Not a directory");
    }
}
