//! Building the `object_store` client for a location: timeouts, retries with backoff, and credentials from where
//! each service's tools look for them.
//!
//! - HTTP(S): credentials only from the URL's user information, sent as a sensitive `Authorization` header.
//! - S3: the `AWS_*` environment variables (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_SESSION_TOKEN`,
//!   `AWS_REGION`/`AWS_DEFAULT_REGION`, `AWS_ENDPOINT_URL` for S3-compatible servers), else the profile files
//!   ([`crate::aws_profile`]); with no credentials anywhere the bucket is read anonymously (public buckets), never
//!   by asking an instance-metadata service that a laptop does not have. The region defaults to `us-east-1`.
//! - GCS and Azure: the environment variables object_store reads (`GOOGLE_SERVICE_ACCOUNT`, `AZURE_STORAGE_*`, …);
//!   GCS without credentials is read anonymously.
//!
//! TLS certificates are verified against the system's roots; plain `http://` is allowed only where the location or
//! the configured endpoint says `http://`.

use std::sync::Arc;
use std::time::Duration;

use object_store::aws::AmazonS3Builder;
use object_store::azure::MicrosoftAzureBuilder;
use object_store::gcp::GoogleCloudStorageBuilder;
use object_store::http::HttpBuilder;
use object_store::{BackoffConfig, ClientOptions, ObjectStore, RetryConfig};

use crate::aws_profile::load_profile;
use crate::error::RemoteError;
use crate::location::{RemoteLocation, Service};
use crate::remote_store::RemoteOptions;

fn env(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

/// The runtime a client's requests run on: two worker threads named `name` (the requests wait on the network, not
/// on the CPU).
pub(crate) fn client_runtime(location: &RemoteLocation, name: &str) -> Result<tokio::runtime::Runtime, RemoteError> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name(name)
        .enable_all()
        .build()
        .map_err(|e| RemoteError::Client { url: location.shown().into(), problem: e.to_string() })
}

/// The client for `location`.
pub(crate) fn build_client(
    location: &RemoteLocation,
    options: &RemoteOptions,
) -> Result<Arc<dyn ObjectStore>, RemoteError> {
    let failed = |e: object_store::Error| RemoteError::Client { url: location.shown().into(), problem: e.to_string() };
    let retry = RetryConfig {
        backoff: BackoffConfig {
            init_backoff: Duration::from_millis(100),
            max_backoff: Duration::from_secs(5),
            base: 2.0,
        },
        max_retries: options.retries,
        retry_timeout: (options.request_timeout + Duration::from_secs(5)) * (options.retries as u32 + 1),
    };
    let user_agent = http::HeaderValue::from_static(concat!("voxstream/", env!("CARGO_PKG_VERSION")));
    let client = ClientOptions::new()
        .with_timeout(options.request_timeout)
        .with_connect_timeout(options.connect_timeout)
        .with_user_agent(user_agent);
    let bucket = location.bucket().unwrap_or_default().to_string();
    let store: Arc<dyn ObjectStore> = match location.service {
        Service::Http => {
            let mut client = client.with_allow_http(location.base.starts_with("http://"));
            if let Some((user, password)) = &location.basic_auth {
                use base64::Engine;
                let token = base64::engine::general_purpose::STANDARD.encode(format!("{user}:{password}"));
                let mut value =
                    http::HeaderValue::from_str(&format!("Basic {token}")).map_err(|_| RemoteError::BadUrl {
                        url: location.shown().into(),
                        problem: "the user or password holds characters a header cannot carry".into(),
                    })?;
                value.set_sensitive(true);
                let mut headers = http::HeaderMap::new();
                headers.insert(http::header::AUTHORIZATION, value);
                client = client.with_default_headers(headers);
            }
            let url = location.base.trim_end_matches('/');
            Arc::new(
                HttpBuilder::new()
                    .with_url(url)
                    .with_client_options(client)
                    .with_retry(retry)
                    .build()
                    .map_err(failed)?,
            )
        }
        Service::S3 => {
            let mut builder = AmazonS3Builder::from_env().with_bucket_name(&bucket).with_retry(retry);
            let has_key = env("AWS_ACCESS_KEY_ID").is_some();
            let profile = if has_key { Default::default() } else { load_profile()? };
            let from_profile = |key: &str| profile.get(key).filter(|v| !v.is_empty()).cloned();
            if let (Some(id), Some(secret)) = (from_profile("aws_access_key_id"), from_profile("aws_secret_access_key"))
            {
                builder = builder.with_access_key_id(id).with_secret_access_key(secret);
                if let Some(token) = from_profile("aws_session_token") {
                    builder = builder.with_token(token);
                }
            }
            let region = env("AWS_REGION").or_else(|| env("AWS_DEFAULT_REGION")).or_else(|| from_profile("region"));
            builder = builder.with_region(region.unwrap_or_else(|| "us-east-1".into()));
            let endpoint =
                env("AWS_ENDPOINT_URL").or_else(|| env("AWS_ENDPOINT")).or_else(|| from_profile("endpoint_url"));
            if let Some(endpoint) = &endpoint {
                builder = builder.with_endpoint(endpoint);
            }
            let anonymous = !has_key
                && from_profile("aws_access_key_id").is_none()
                && env("AWS_WEB_IDENTITY_TOKEN_FILE").is_none()
                && env("AWS_CONTAINER_CREDENTIALS_RELATIVE_URI").is_none()
                && env("AWS_CONTAINER_CREDENTIALS_FULL_URI").is_none();
            if anonymous {
                builder = builder.with_skip_signature(true);
            }
            let plain_http = endpoint.as_deref().is_some_and(|e| e.starts_with("http://"));
            let client = client.with_allow_http(plain_http || env("AWS_ALLOW_HTTP").is_some_and(|v| v == "true"));
            Arc::new(builder.with_client_options(client).build().map_err(failed)?)
        }
        Service::Gcs => {
            let mut builder = GoogleCloudStorageBuilder::from_env().with_bucket_name(&bucket).with_retry(retry);
            let has_credentials = [
                "GOOGLE_SERVICE_ACCOUNT",
                "GOOGLE_SERVICE_ACCOUNT_PATH",
                "GOOGLE_SERVICE_ACCOUNT_KEY",
                "GOOGLE_APPLICATION_CREDENTIALS",
            ]
            .iter()
            .any(|v| env(v).is_some());
            if !has_credentials {
                builder = builder.with_skip_signature(true);
            }
            Arc::new(builder.with_client_options(client).build().map_err(failed)?)
        }
        Service::Azure => {
            let builder = MicrosoftAzureBuilder::from_env().with_container_name(&bucket).with_retry(retry);
            Arc::new(builder.with_client_options(client).build().map_err(failed)?)
        }
    };
    Ok(store)
}
