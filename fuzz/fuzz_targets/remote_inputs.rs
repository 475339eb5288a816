//! Remote-store inputs (issue 43): store locations (URLs typed by users or found in scripts) and disk-cache entries
//! (files in a folder other processes write too). Neither may panic; a parsed location shows no user information;
//! an entry decodes only for its own key and length.
#![no_main]

use libfuzzer_sys::fuzz_target;
use voxstream_store::remote::{disk_cache::decode, RemoteLocation};

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(Some(location)) = RemoteLocation::parse(text) {
            // What is shown is rebuilt from the parts, never the text given: no user information in it.
            let authority = location.shown().split("://").nth(1).unwrap_or("").split('/').next().unwrap_or("");
            assert!(!authority.contains('@'), "user information shown: {}", location.shown());
        }
        let _ = voxstream_store::remote::redact(text);
    }
    let split = data.first().copied().unwrap_or(0) as usize % (data.len().max(1));
    let key = String::from_utf8_lossy(&data[..split]);
    if let Some(bytes) = decode(data, &key) {
        assert!(bytes.len() <= data.len());
    }
});
