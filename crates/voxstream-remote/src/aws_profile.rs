//! AWS credentials and settings from the shared profile files (`~/.aws/credentials`, `~/.aws/config`), for S3
//! locations when the environment gives none.
//!
//! object_store reads the `AWS_*` environment variables but not the profile files, and the AWS SDK's loader
//! (`aws-config`) would bring the whole SDK for two INI files: this reads the keys voxstream needs from the profile
//! `AWS_PROFILE` names (`default` otherwise): `aws_access_key_id`, `aws_secret_access_key`, `aws_session_token`,
//! `region` and `endpoint_url`. Files are held to 1 MiB. The values are never shown.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::RemoteError;

/// Largest profile file read, bytes.
const MAX_PROFILE_BYTES: u64 = 1 << 20;

/// The settings of one profile (keys lower-case, as in the files).
pub type Profile = HashMap<String, String>;

/// The section `wanted` of an INI text (`[wanted]`, or `[profile wanted]` as `~/.aws/config` names them).
pub fn parse_section(text: &str, wanted: &str) -> Profile {
    let mut inside = false;
    let mut found = Profile::new();
    for line in text.lines() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with(';') {
            continue;
        }
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            let name = name.trim();
            inside = name == wanted || name.strip_prefix("profile ").map(str::trim) == Some(wanted);
            continue;
        }
        if inside {
            if let Some((key, value)) = line.split_once('=') {
                found.insert(key.trim().to_ascii_lowercase(), value.trim().to_string());
            }
        }
    }
    found
}

fn read_capped(path: &Path) -> Result<Option<String>, RemoteError> {
    let bad = |problem: String| RemoteError::Profile { path: path.display().to_string(), problem };
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(bad(e.to_string())),
        Ok(m) if !m.is_file() => Err(bad("not a regular file".into())),
        Ok(m) if m.len() > MAX_PROFILE_BYTES => {
            Err(bad(format!("{} bytes, over the 1 MiB a profile file may take", m.len())))
        }
        Ok(_) => std::fs::read_to_string(path).map(Some).map_err(|e| bad(e.to_string())),
    }
}

/// The AWS profile's settings from the credentials and config files (credentials win), or an empty map when
/// neither file exists. `AWS_SHARED_CREDENTIALS_FILE` and `AWS_CONFIG_FILE` name other files, as for the AWS CLI.
pub fn load_profile() -> Result<Profile, RemoteError> {
    let home = std::env::var_os("HOME").map(PathBuf::from);
    let file = |variable: &str, default: &str| {
        std::env::var_os(variable).map(PathBuf::from).or_else(|| home.as_ref().map(|h| h.join(".aws").join(default)))
    };
    let name = std::env::var("AWS_PROFILE").unwrap_or_else(|_| "default".into());
    let mut profile = Profile::new();
    for path in
        [file("AWS_CONFIG_FILE", "config"), file("AWS_SHARED_CREDENTIALS_FILE", "credentials")].into_iter().flatten()
    {
        if let Some(text) = read_capped(&path)? {
            profile.extend(parse_section(&text, &name));
        }
    }
    Ok(profile)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_are_read_by_name_in_both_files_styles() {
        let credentials =
            "[default]\naws_access_key_id = A\n\n[work]\naws_access_key_id=B\naws_secret_access_key = S\n";
        assert_eq!(parse_section(credentials, "work").get("aws_access_key_id").map(String::as_str), Some("B"));
        assert_eq!(parse_section(credentials, "default").len(), 1);
        let config = "# comment\n[profile work]\nregion = eu-west-1\nendpoint_url = http://127.0.0.1:9000\n";
        let work = parse_section(config, "work");
        assert_eq!(work.get("region").map(String::as_str), Some("eu-west-1"));
        assert_eq!(work.get("endpoint_url").map(String::as_str), Some("http://127.0.0.1:9000"));
        assert!(parse_section(config, "other").is_empty());
    }
}
