//! Where a remote store lives: `http(s)://host/path`, `s3://bucket/prefix`, `gs://bucket/prefix` or
//! `az://container/prefix`, parsed once, with any credentials in the URL taken out of it.
//!
//! A store is named by the URL of its root folder (the one holding `zarr.json` or `.zattrs`). A user name and
//! password in an HTTP URL (`https://user:secret@host/…`) are kept apart from the URL and sent as an
//! `Authorization` header, so that no error, log line or statistic, which all show [`RemoteLocation::shown`], can
//! carry them; query strings (pre-signed URLs' signatures) are dropped from what is shown too.

use url::Url;

use crate::error::RemoteError;

/// The kind of service a remote store is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Service {
    /// Any HTTP(S) server that honours byte ranges (nginx, S3 or GCS public URLs, a CDN).
    Http,
    /// Amazon S3 or an S3-compatible server (MinIO, Ceph, moto).
    S3,
    /// Google Cloud Storage.
    Gcs,
    /// Azure Blob Storage.
    Azure,
}

/// A parsed remote store location.
#[derive(Clone, PartialEq, Eq)]
pub struct RemoteLocation {
    /// Which client reads it.
    pub service: Service,
    /// For HTTP: the store's root URL without user information, ending in `/`. For the others: `scheme://bucket`.
    pub base: String,
    /// The store's folder inside the bucket (no leading or trailing `/`); empty for HTTP (part of `base`).
    pub prefix: String,
    /// HTTP basic credentials given in the URL (user, password), never shown.
    pub basic_auth: Option<(String, String)>,
    shown: String,
}

impl std::fmt::Debug for RemoteLocation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never the credentials, even in debug output.
        f.debug_struct("RemoteLocation").field("service", &self.service).field("shown", &self.shown).finish()
    }
}

/// Whether `text` names a remote store (starts with a URL scheme voxstream reads), whatever follows.
pub fn is_remote(text: &str) -> bool {
    let lower = text.get(..8).unwrap_or(text).to_ascii_lowercase();
    ["http://", "https://", "s3://", "gs://", "az://"].iter().any(|scheme| lower.starts_with(scheme))
}

impl RemoteLocation {
    /// Parses `text`; `Ok(None)` when it is not a remote location (a local path).
    pub fn parse(text: &str) -> Result<Option<RemoteLocation>, RemoteError> {
        if !is_remote(text) {
            return Ok(None);
        }
        let bad = |problem: &str| RemoteError::BadUrl { url: redact(text), problem: problem.to_string() };
        let url = Url::parse(text).map_err(|e| bad(&e.to_string()))?;
        let service = match url.scheme() {
            "http" | "https" => Service::Http,
            "s3" => Service::S3,
            "gs" => Service::Gcs,
            "az" => Service::Azure,
            _ => return Err(bad("unsupported scheme (http, https, s3, gs and az are read)")),
        };
        let host = url.host_str().filter(|h| !h.is_empty()).ok_or_else(|| {
            bad(match service {
                Service::Http => "no host",
                Service::S3 | Service::Gcs => "no bucket (s3://BUCKET/PREFIX)",
                Service::Azure => "no container (az://CONTAINER/PREFIX)",
            })
        })?;
        let path = url.path().trim_matches('/');
        if path.split('/').any(|part| part == "..") {
            return Err(bad("the path holds '..'"));
        }
        let user = url.username();
        let basic_auth = if user.is_empty() && url.password().is_none() {
            None
        } else if service == Service::Http {
            let decode =
                |s: &str| url::form_urlencoded::parse(format!("x={s}").as_bytes()).next().map(|(_, v)| v.into_owned());
            Some((decode(user).unwrap_or_default(), decode(url.password().unwrap_or("")).unwrap_or_default()))
        } else {
            return Err(bad(
                "credentials in an s3://, gs:// or az:// URL are not read: use the service's environment variables \
                 or profile files (for S3: AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY, or AWS_PROFILE)",
            ));
        };
        let port = url.port().map(|p| format!(":{p}")).unwrap_or_default();
        let (base, prefix) = match service {
            Service::Http => {
                let folder = if path.is_empty() { String::new() } else { format!("{path}/") };
                (format!("{}://{host}{port}/{folder}", url.scheme()), String::new())
            }
            _ => (format!("{}://{host}", url.scheme()), path.to_string()),
        };
        let shown = match service {
            Service::Http => base.trim_end_matches('/').to_string(),
            _ if prefix.is_empty() => base.clone(),
            _ => format!("{base}/{prefix}"),
        };
        Ok(Some(RemoteLocation { service, base, prefix, basic_auth, shown }))
    }

    /// The location as shown in messages and statistics: no credentials, no query string.
    pub fn shown(&self) -> &str {
        &self.shown
    }

    /// The bucket (S3, GCS) or container (Azure); `None` for HTTP.
    pub fn bucket(&self) -> Option<&str> {
        match self.service {
            Service::Http => None,
            _ => self.base.split("://").nth(1),
        }
    }

    /// Whether the service lists folders (object stores do; plain HTTP servers do not).
    pub fn can_list(&self) -> bool {
        self.service != Service::Http
    }
}

/// `text` with user information and the query string taken out, for messages about a URL that did not parse; a
/// local path as it is.
pub fn redact(text: &str) -> String {
    if !is_remote(text) {
        return text.to_string();
    }
    let without_query = text.split(['?', '#']).next().unwrap_or(text);
    match without_query.find("://") {
        Some(scheme_end) => {
            let rest = &without_query[scheme_end + 3..];
            let authority_end = rest.find('/').unwrap_or(rest.len());
            match rest[..authority_end].rfind('@') {
                Some(at) => format!("{}://***@{}", &without_query[..scheme_end], &rest[at + 1..]),
                None => without_query.to_string(),
            }
        }
        None => without_query.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_parse_into_services_bases_and_prefixes() {
        let http = RemoteLocation::parse("https://example.org/data/brain.zarr/").unwrap().unwrap();
        assert_eq!(
            (http.service, http.base.as_str(), http.prefix.as_str()),
            (Service::Http, "https://example.org/data/brain.zarr/", "")
        );
        assert_eq!(http.shown(), "https://example.org/data/brain.zarr");
        let s3 = RemoteLocation::parse("s3://bucket/scans/ct.zarr").unwrap().unwrap();
        assert_eq!((s3.service, s3.base.as_str(), s3.prefix.as_str()), (Service::S3, "s3://bucket", "scans/ct.zarr"));
        assert_eq!(s3.bucket(), Some("bucket"));
        let port = RemoteLocation::parse("http://127.0.0.1:8080/s.zarr").unwrap().unwrap();
        assert_eq!(port.base, "http://127.0.0.1:8080/s.zarr/");
        assert!(RemoteLocation::parse("data/s.zarr").unwrap().is_none(), "a local path is not remote");
        assert!(RemoteLocation::parse("/tmp/http:/x").unwrap().is_none());
        assert!(is_remote("HTTPS://EXAMPLE.ORG/x"));
    }

    #[test]
    fn credentials_never_reach_what_is_shown() {
        let located = RemoteLocation::parse("https://alice:s3cr%40t@example.org/s.zarr?sig=abc").unwrap().unwrap();
        assert_eq!(located.basic_auth, Some(("alice".into(), "s3cr@t".into())));
        assert!(!located.shown().contains("s3cr"), "{}", located.shown());
        assert!(!located.base.contains("alice") && !located.base.contains("sig=abc"));
        assert!(!format!("{located:?}").contains("s3cr"));
        assert_eq!(redact("https://alice:secret@example.org/x?sig=1"), "https://***@example.org/x");
        let refused = RemoteLocation::parse("s3://key:secret@bucket/x").unwrap_err().to_string();
        assert!(!refused.contains("secret") && refused.contains("AWS_ACCESS_KEY_ID"), "{refused}");
    }

    #[test]
    fn malformed_locations_name_the_problem() {
        let no_bucket = RemoteLocation::parse("s3:///x").unwrap_err().to_string();
        assert!(no_bucket.contains("no bucket"), "{no_bucket}");
        assert!(
            RemoteLocation::parse("https://example.org/a/../b").is_err() || {
                // The URL parser resolves '..' itself: what remains must not leave the host's root.
                let parsed = RemoteLocation::parse("https://example.org/a/../b").unwrap().unwrap();
                parsed.base == "https://example.org/b/"
            }
        );
        assert!(RemoteLocation::parse("http://").is_err());
    }
}
