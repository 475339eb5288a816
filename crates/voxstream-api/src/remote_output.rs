//! Imports whose `out` is a remote location (`s3://BUCKET/NAME.zarr`, `gs://…`, `az://…`): the store is built in a
//! temporary folder under `$TMPDIR` (it needs the store's size there), then uploaded by
//! [`voxstream_remote::StoreUpload`], its root `zarr.json` last, and the folder removed (also when anything fails).
//!
//! A remote `out` is checked before the input is read: HTTP(S) (read-only), a bare bucket, a location already
//! holding a store and `overwrite` are refused in one line each, and the bucket has answered with the credentials
//! given. Before this, `--out s3://b/x.zarr` silently wrote a local folder named `s3:`.

use std::ops::ControlFlow;
use std::path::Path;

use anyhow::{bail, Context, Result};
use voxstream_remote::{RemoteLocation, RemoteOptions, StoreUpload, UploadReport};
use voxstream_store::ImportReport;

use crate::import_input::{ImportInput, ImportSettings};

/// A checked remote destination for an import.
#[derive(Debug)]
pub struct RemoteOutput {
    upload: StoreUpload,
}

/// `Ok(None)` where `out` is a local folder; else the remote destination, checked (see the module).
pub fn remote_output(out: &Path, settings: &ImportSettings) -> Result<Option<RemoteOutput>> {
    let Some(text) = out.to_str().filter(|t| voxstream_remote::is_remote(t)) else {
        return Ok(None);
    };
    let Some(location) = RemoteLocation::parse(text)? else {
        return Ok(None);
    };
    if settings.overwrite {
        bail!(
            "{}: --overwrite does not apply to a remote store (object storage cannot swap a store in whole, so \
             voxstream never replaces one in place): delete it first, or give another --out",
            location.shown()
        );
    }
    let upload = StoreUpload::open(location, &RemoteOptions::default())?;
    upload.check_free()?;
    Ok(Some(RemoteOutput { upload }))
}

impl RemoteOutput {
    /// Where the store goes, as shown (no credentials).
    pub fn shown(&self) -> &str {
        self.upload.location().shown()
    }

    /// Imports `input` into a temporary folder, then uploads it; `progress` hears input bytes (and may stop the
    /// import, as [`ImportInput::import`]'s), `uploaded(done, total)` the bytes put.
    pub fn import(
        &self,
        input: ImportInput,
        settings: &ImportSettings,
        progress: &mut (dyn FnMut(u64, u64) -> ControlFlow<()> + Send),
        uploaded: &mut (dyn FnMut(u64, u64) + Send),
    ) -> Result<(ImportReport, UploadReport)> {
        let folder = tempfile::Builder::new().prefix("voxstream-upload-").tempdir().with_context(|| {
            format!("{}: cannot make a temporary folder for the store", std::env::temp_dir().display())
        })?;
        let local = folder.path().join("store.zarr");
        let report = input.import(&local, settings, progress)?;
        let upload = self.upload.upload(&local, uploaded)?;
        Ok((report, upload))
    }
}
