//! Remote stores over real servers (issue 43): nginx serving a folder over HTTP with byte ranges and ETags (Debian's
//! `nginx-light`, run unprivileged from a config in a scratch folder), moto's S3 server (`moto_server`, from PyPI,
//! in `data/venv`), and `scripts/fault_proxy.py` between them and voxstream for latency, 503s, truncated bodies and
//! stalls. The images from HTTP and S3 must be the local folder's, byte for byte, faults or not; a dead server must
//! end the run with one clear line, never a hang; credentials never reach what voxstream prints.
//!
//! `.ci/run` installs nginx-light; `scripts/fetch-real-data.sh` installs moto, boto3 and zarr into `data/venv`.

mod common;

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{data_folder, import_ball, repository_root, scratch, stderr, voxstream};

const NGINX: &str = "/usr/sbin/nginx";

/// The project's Python environment (moto, boto3, zarr), made by `scripts/fetch-real-data.sh`.
fn venv_python() -> PathBuf {
    let python = data_folder().join("venv/bin/python");
    assert!(
        python.exists(),
        "data/venv is missing: run scripts/fetch-real-data.sh (it installs moto, boto3 and zarr there)"
    );
    python
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Waits until something listens on `port` (at most 30 s).
fn wait_for_port(port: u16, child: &mut Child, what: &str) {
    let start = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("{what} exited before listening ({status})");
        }
        assert!(start.elapsed() < Duration::from_secs(30), "{what} did not listen on {port} within 30 s");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A server process, killed when dropped.
struct Server {
    child: Child,
    port: u16,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// nginx serving `root` on a free port, its access log at `dir/access.log`.
fn nginx(dir: &Path, root: &Path) -> Server {
    nginx_serving(dir, root, None)
}

/// A certificate authority's certificate (PEM) and nginx's certificate and key (PEM) signed by it, for 127.0.0.1.
fn certificates() -> (String, String, String) {
    use rcgen::{BasicConstraints, CertificateParams, IsCa, KeyPair, SanType};
    let ca_key = KeyPair::generate().unwrap();
    let mut ca = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca.distinguished_name.push(rcgen::DnType::CommonName, "voxstream test CA");
    let ca_cert = ca.self_signed(&ca_key).unwrap();
    let issuer = rcgen::Issuer::new(ca, ca_key);
    let server_key = KeyPair::generate().unwrap();
    let mut server = CertificateParams::new(vec!["localhost".to_string()]).unwrap();
    server.subject_alt_names.push(SanType::IpAddress(std::net::Ipv4Addr::LOCALHOST.into()));
    let server_cert = server.signed_by(&server_key, &issuer).unwrap();
    (ca_cert.pem(), server_cert.pem(), server_key.serialize_pem())
}

/// nginx serving `root` on a free port, over HTTPS with `tls`'s certificate and key files where given.
fn nginx_serving(dir: &Path, root: &Path, tls: Option<(&Path, &Path)>) -> Server {
    assert!(Path::new(NGINX).exists(), "nginx is missing: sudo apt-get install nginx-light (.ci/run installs it)");
    let port = free_port();
    let prefix = dir.join("nginx");
    std::fs::create_dir_all(&prefix).unwrap();
    let p = prefix.display();
    let config = format!(
        "daemon off;\nmaster_process off;\npid {p}/nginx.pid;\nerror_log {p}/error.log;\nevents {{ worker_connections \
         512; }}\nhttp {{\n  log_format ranges '$request \"$http_range\" $status';\n  access_log {p}/access.log ranges;\n  client_body_temp_path {p}/body;\n  proxy_temp_path \
         {p}/proxy;\n  fastcgi_temp_path {p}/fastcgi;\n  uwsgi_temp_path {p}/uwsgi;\n  scgi_temp_path {p}/scgi;\n  \
         server {{ listen 127.0.0.1:{port}{}; {} root {}; location / {{ }} }}\n}}\n",
        if tls.is_some() { " ssl" } else { "" },
        tls.map_or(String::new(), |(cert, key)| format!(
            "ssl_certificate {}; ssl_certificate_key {};",
            cert.display(),
            key.display()
        )),
        root.display()
    );
    std::fs::write(prefix.join("nginx.conf"), config).unwrap();
    let mut child = Command::new(NGINX)
        .args(["-p", &p.to_string(), "-c", &format!("{p}/nginx.conf"), "-e", &format!("{p}/error.log")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start nginx");
    wait_for_port(port, &mut child, "nginx");
    Server { child, port }
}

/// moto's S3 server on a free port.
fn moto() -> Server {
    let python = venv_python();
    let port = free_port();
    let mut child = Command::new(python.with_file_name("moto_server"))
        .args(["-H", "127.0.0.1", "-p", &port.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start moto_server (data/venv: scripts/fetch-real-data.sh installs it)");
    wait_for_port(port, &mut child, "moto_server");
    Server { child, port }
}

/// The fault proxy in front of `upstream`, with `flags`, logging to `log`.
fn proxy(upstream: u16, flags: &[&str], log: &Path) -> Server {
    let port = free_port();
    let mut child = Command::new("python3")
        .arg(repository_root().join("scripts/fault_proxy.py"))
        .args(["--listen", &port.to_string(), "--upstream", &format!("127.0.0.1:{upstream}")])
        .args(["--log", &log.display().to_string()])
        .args(flags)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start scripts/fault_proxy.py");
    wait_for_port(port, &mut child, "fault_proxy.py");
    Server { child, port }
}

/// Uploads the folder `root` to `s3://bucket/prefix` on moto at `port` with boto3 (an independent S3 client).
fn upload(port: u16, root: &Path, bucket: &str, prefix: &str) {
    let script = r#"
import boto3, os, sys
root, bucket, prefix, endpoint = sys.argv[1:5]
s3 = boto3.client("s3", endpoint_url=endpoint, aws_access_key_id="test", aws_secret_access_key="test",
                  region_name="us-east-1")
s3.create_bucket(Bucket=bucket)
for folder, _, files in os.walk(root):
    for name in files:
        path = os.path.join(folder, name)
        s3.upload_file(path, bucket, prefix + "/" + os.path.relpath(path, root).replace(os.sep, "/"))
"#;
    let status = Command::new(venv_python())
        .args(["-c", script, &root.display().to_string(), bucket, prefix, &format!("http://127.0.0.1:{port}")])
        .status()
        .unwrap();
    assert!(status.success(), "uploading to moto failed");
}

/// Renders `source` converged at 96² into `dir/out`, returning the PNG's bytes and the run's output.
fn render(
    dir: &Path,
    source: &str,
    out: &str,
    extra: &[&str],
    env: &[(&str, &str)],
) -> (Vec<u8>, std::process::Output) {
    let mut command = Command::new(env!("CARGO_BIN_EXE_voxstream"));
    command.args(["render", source, "--out", out, "--width", "96", "--height", "96", "--quiet"]).args(extra);
    for (k, v) in env {
        command.env(k, v);
    }
    let output = command.current_dir(dir).output().unwrap();
    let png = std::fs::read(dir.join(out)).unwrap_or_default();
    (png, output)
}

fn s3_env(port: u16) -> Vec<(&'static str, String)> {
    vec![
        ("AWS_ACCESS_KEY_ID", "test".into()),
        ("AWS_SECRET_ACCESS_KEY", "s3cretValue".into()),
        ("AWS_ENDPOINT_URL", format!("http://127.0.0.1:{port}")),
        ("AWS_REGION", "us-east-1".into()),
    ]
}

/// For an nginx log line `GET /STORE/LEVEL/c/Z/Y/X HTTP/1.1 "bytes=A-B" 206` of a shard served from `root`: how
/// many bricks the range holds by the shard's index if it is exactly whole bricks, 0 if it is not; `None` for
/// other lines (a suffix read of the index, metadata).
fn bricks_in_range(root: &Path, line: &str) -> Option<usize> {
    let path = line.split(' ').nth(1)?.trim_start_matches('/');
    let range = line.split("\"bytes=").nth(1)?.split('"').next()?;
    let (first, last) = range.split_once('-')?;
    let (first, last): (u64, u64) = (first.parse().ok()?, last.parse().ok()?);
    let (store_and_level, _) = path.split_once("/c/")?;
    let level: serde_json::Value =
        serde_json::from_slice(&std::fs::read(root.join(store_and_level).join("zarr.json")).ok()?).ok()?;
    let shape =
        |v: &serde_json::Value| -> Vec<u64> { v.as_array().unwrap().iter().map(|e| e.as_u64().unwrap()).collect() };
    let outer = shape(&level["chunk_grid"]["configuration"]["chunk_shape"]);
    let inner = shape(&level["codecs"][0]["configuration"]["chunk_shape"]);
    let count: u64 = outer.iter().zip(&inner).map(|(o, i)| o / i).product();
    let shard = std::fs::read(root.join(path)).unwrap();
    let index = &shard[shard.len() - (16 * count as usize + 4)..];
    let (mut held, mut bytes) = (0, 0);
    for entry in index[..16 * count as usize].chunks_exact(16) {
        let offset = u64::from_le_bytes(entry[..8].try_into().unwrap());
        let length = u64::from_le_bytes(entry[8..].try_into().unwrap());
        if offset != u64::MAX && offset >= first && offset + length <= last + 1 {
            held += 1;
            bytes += length;
        }
    }
    Some(if bytes == last + 1 - first { held } else { 0 })
}

#[test]
fn http_and_s3_give_the_local_image_byte_for_byte() {
    let dir = scratch("remote_stores", "identical");
    import_ball(&dir, "www/ball.zarr");
    let (local, out) = render(&dir, "www/ball.zarr", "local.png", &[], &[]);
    assert!(out.status.success() && !local.is_empty(), "local render: {}", stderr(&out));

    let server = nginx(&dir, &dir.join("www"));
    let url = format!("http://127.0.0.1:{}/ball.zarr", server.port);
    let (http, out) = render(&dir, &url, "http.png", &["--stats", "http.json"], &[]);
    assert!(out.status.success(), "HTTP render: {}", stderr(&out));
    assert!(http == local, "the image over HTTP differs from the local folder's");
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("http.json")).unwrap()).unwrap();
    let requests = stats["remote"]["requests"].as_u64().expect("remote requests in --stats");
    assert!(requests > 0 && stats["remote"]["failures"] == 0, "{}", stats["remote"]);
    // Each shard index is fetched once, and no brick twice: every (chunk, range) is requested once.
    let log = std::fs::read_to_string(dir.join("nginx/access.log")).unwrap();
    let lines: Vec<&str> = log.lines().filter(|l| l.starts_with("GET") && l.contains("/c/")).collect();
    let distinct: std::collections::HashSet<&str> = lines.iter().copied().collect();
    assert!(!lines.is_empty(), "no chunk was fetched: {log}");
    // Bricks that abut in a shard come in one request, and every request is whole bricks, no byte more.
    let spans: Vec<usize> = lines.iter().filter_map(|line| bricks_in_range(&dir.join("www"), line)).collect();
    assert!(spans.iter().all(|&n| n > 0), "a range that is not whole bricks: {spans:?}\n{log}");
    assert!(spans.iter().any(|&n| n > 1), "no request held more than one brick: {spans:?}\n{log}");

    let s3 = moto();
    upload(s3.port, &dir.join("www/ball.zarr"), "scans", "volumes/ball.zarr");
    let env = s3_env(s3.port);
    let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let (from_s3, out) = render(&dir, "s3://scans/volumes/ball.zarr", "s3.png", &[], &env);
    assert!(out.status.success(), "S3 render: {}", stderr(&out));
    assert!(from_s3 == local, "the image from S3 differs from the local folder's");
    // `info` lists the chunks over S3 (HTTP cannot list) and shows no secret.
    let info = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["info", "s3://scans/volumes/ball.zarr"])
        .envs(env.iter().copied())
        .output()
        .unwrap();
    assert!(info.status.success(), "info over S3: {}", stderr(&info));
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("s3://scans/volumes/ball.zarr") && text.contains("48 x 40 x 36"), "{text}");
    assert!(!text.contains("s3cretValue") && !stderr(&info).contains("s3cretValue"));
    assert_eq!(lines.len(), distinct.len(), "a chunk range was fetched twice:\n{log}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_wavelet_coded_store_over_http_renders_the_local_image_byte_for_byte() {
    // Issue 47: the compressed bytes travel as they are stored, decoded by the same codec as from a folder.
    let dir = scratch("remote_stores", "wavelet");
    import_ball(&dir, "ball.zarr");
    let out = voxstream(
        &[
            "import",
            "ball.nrrd",
            "--out",
            "www/lossy.zarr",
            "--brick-size",
            "16",
            "--codec",
            "wavelet",
            "--max-error",
            "5",
        ],
        &dir,
    );
    assert!(out.status.success(), "import: {}", stderr(&out));
    let (local, out) = render(&dir, "www/lossy.zarr", "local.png", &[], &[]);
    assert!(out.status.success() && !local.is_empty(), "local render: {}", stderr(&out));
    let server = nginx(&dir, &dir.join("www"));
    let url = format!("http://127.0.0.1:{}/lossy.zarr", server.port);
    let (http, out) = render(&dir, &url, "http.png", &["--stats", "http.json"], &[]);
    assert!(out.status.success(), "HTTP render: {}", stderr(&out));
    assert!(http == local, "the wavelet store's image over HTTP differs from the local folder's");
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("http.json")).unwrap()).unwrap();
    assert!(stats["remote"]["failures"] == 0, "{}", stats["remote"]);
    let info = Command::new(env!("CARGO_BIN_EXE_voxstream")).args(["info", &url, "--json"]).output().unwrap();
    assert!(info.status.success(), "info over HTTP: {}", stderr(&info));
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(info["brick_codec"], serde_json::json!({"name": "wavelet", "max_error": 5.0}));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every shard file under `level_dir` (`…/c/z/y/x`), as its path below `store` with `/` separators.
fn shard_files(store: &Path, level_dir: &Path, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(level_dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            shard_files(store, &path, out);
        } else if path.strip_prefix(store).unwrap().components().nth(1).is_some_and(|c| c.as_os_str() == "c") {
            out.push(path.strip_prefix(store).unwrap().to_string_lossy().replace('\\', "/"));
        }
    }
}

#[test]
fn opening_a_remote_store_fetches_its_shard_indexes_with_the_level_probes() {
    // Opening reads every shard index the coarse levels have (at most 256), while the levels are probed, so that a
    // render waits one round trip per brick of those levels, not two: `info` opens the store and reads nothing else.
    let dir = scratch("remote_stores", "indexes");
    import_ball(&dir, "www/ball.zarr");
    let store = dir.join("www/ball.zarr");
    let mut shards = Vec::new();
    for level in ["0", "1", "2"] {
        shard_files(&store, &store.join(level), &mut shards);
    }
    shards.sort();
    assert!(shards.len() >= 3, "the ball's store has shards at each of its levels: {shards:?}");
    let server = nginx(&dir, &dir.join("www"));
    let out = voxstream(&["info", &format!("http://127.0.0.1:{}/ball.zarr", server.port)], &dir);
    assert!(out.status.success(), "info over HTTP: {}", stderr(&out));
    let log = std::fs::read_to_string(dir.join("nginx/access.log")).unwrap();
    // Suffix reads (`bytes=-N`) are shard indexes; each is asked for once.
    let mut indexes: Vec<String> = log
        .lines()
        .filter(|l| l.contains("\"bytes=-"))
        .filter_map(|l| l.split_whitespace().nth(1))
        .map(|path| path.trim_start_matches("/ball.zarr/").to_string())
        .collect();
    indexes.sort();
    assert_eq!(indexes, shards, "shard indexes fetched at open, against the shards stored:\n{log}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_remote_min_max_chunk_of_the_wrong_length_is_refused_in_one_line() {
    // The open reads each level's min/max chunk ahead of its metadata, held to the length the bricks need: a longer
    // (forged) or shorter (truncated) chunk is refused as in a local folder, naming the file and both lengths.
    let dir = scratch("remote_stores", "minmax");
    import_ball(&dir, "www/ball.zarr");
    let chunk = dir.join("www/ball.zarr/voxstream_minmax/0/c/0/0/0/0");
    let stored = std::fs::read(&chunk).unwrap();
    let server = nginx(&dir, &dir.join("www"));
    let url = format!("http://127.0.0.1:{}/ball.zarr", server.port);
    for bytes in [[stored.as_slice(), &[0u8; 4096]].concat(), stored[..stored.len() - 8].to_vec()] {
        std::fs::write(&chunk, &bytes).unwrap();
        let out = voxstream(&["info", &url], &dir);
        let message = stderr(&out);
        assert!(!out.status.success(), "a min/max chunk of {} bytes was taken: {message}", bytes.len());
        assert_eq!(message.trim().lines().count(), 1, "{message}");
        let lengths = format!("holds {} bytes, expected {}", bytes.len(), stored.len());
        assert!(message.contains(&lengths) && message.contains("voxstream_minmax/0"), "{message}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Creates `bucket` on moto at `port` with boto3.
fn create_bucket(port: u16, bucket: &str) {
    let script = r#"
import boto3, sys
bucket, endpoint = sys.argv[1:3]
boto3.client("s3", endpoint_url=endpoint, aws_access_key_id="test", aws_secret_access_key="test",
             region_name="us-east-1").create_bucket(Bucket=bucket)
"#;
    let status =
        Command::new(venv_python()).args(["-c", script, bucket, &format!("http://127.0.0.1:{port}")]).status().unwrap();
    assert!(status.success(), "creating a bucket on moto failed");
}

/// Issue 43: `import --out s3://…` wrote a local folder named `s3:` and said it had imported into S3. The store is
/// now built in a temporary folder and uploaded, its root `zarr.json` last; what S3 holds renders as the local
/// import, byte for byte, and what cannot be written is refused in one line before the input is read.
#[test]
fn import_writes_a_store_to_s3_that_renders_as_the_local_folder() {
    let dir = scratch("remote_stores", "import-s3");
    import_ball(&dir, "ball.zarr");
    let (local, out) = render(&dir, "ball.zarr", "local.png", &[], &[]);
    assert!(out.status.success() && !local.is_empty(), "local render: {}", stderr(&out));
    let s3 = moto();
    create_bucket(s3.port, "scans");
    let env = s3_env(s3.port);
    let import = |out: &str, extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_voxstream"))
            .args(["import", "ball.nrrd", "--out", out, "--brick-size", "16"])
            .args(extra)
            .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
            .current_dir(&dir)
            .output()
            .unwrap()
    };
    let output = import("s3://scans/imported/ball.zarr", &[]);
    let text = stderr(&output);
    assert!(output.status.success(), "import to S3: {text}");
    assert!(text.contains("into s3://scans/imported/ball.zarr") && text.contains("objects ("), "{text}");
    assert!(!text.contains("s3cretValue"), "a secret in the output: {text}");
    assert!(!dir.join("s3:").exists(), "a local folder named s3: was written");
    let env_refs: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let (from_s3, out) = render(&dir, "s3://scans/imported/ball.zarr", "s3.png", &[], &env_refs);
    assert!(out.status.success(), "S3 render: {}", stderr(&out));
    assert!(from_s3 == local, "the store imported into S3 renders differently from the local import");
    // What cannot be written: one line each, a non-zero exit, nothing written.
    for (out, extra, needle) in [
        ("s3://scans/imported/ball.zarr", &[][..], "a store is already there (zarr.json): give another --out"),
        ("s3://scans/other.zarr", &["--overwrite"][..], "--overwrite does not apply to a remote store"),
        ("s3://missing/ball.zarr", &[][..], "the bucket missing does not exist: create it first"),
        ("s3://scans", &[][..], "name the store's folder in the bucket"),
        ("http://127.0.0.1:9/ball.zarr", &[][..], "HTTP(S) stores are read-only"),
    ] {
        let output = import(out, extra);
        let text = stderr(&output);
        assert!(!output.status.success(), "{out} {extra:?}: {text}");
        assert_eq!(text.lines().count(), 1, "{out} {extra:?}: one line expected: {text}");
        assert!(text.starts_with("error: ") && text.contains(needle), "{out} {extra:?}: {text}");
    }
    let (_, out) = render(&dir, "s3://scans/other.zarr", "none.png", &[], &env_refs);
    assert!(!out.status.success(), "a refused import wrote a store");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn https_certificates_are_verified_and_a_trusted_one_reads_the_local_image() {
    let dir = scratch("remote_stores", "https");
    import_ball(&dir, "www/ball.zarr");
    let (local, out) = render(&dir, "www/ball.zarr", "local.png", &[], &[]);
    assert!(out.status.success() && !local.is_empty(), "local render: {}", stderr(&out));
    let (ca, cert, key) = certificates();
    for (name, pem) in [("ca.pem", &ca), ("server.pem", &cert), ("server.key", &key)] {
        std::fs::write(dir.join(name), pem).unwrap();
    }
    let server = nginx_serving(&dir, &dir.join("www"), Some((&dir.join("server.pem"), &dir.join("server.key"))));
    let url = format!("https://127.0.0.1:{}/ball.zarr", server.port);
    // A certificate no root the client trusts signed: refused in one line naming the cause and the fix, and no
    // chunk fetched. (SSL_CERT_FILE names the roots instead of the system's; the system's do not hold the test CA.)
    let (_, out) = render(&dir, &url, "untrusted.png", &["--retries", "0"], &[]);
    let message = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{message}");
    assert_eq!(message.trim().lines().count(), 1, "not one line: {message}");
    assert!(message.contains("certificate") && message.contains("SSL_CERT_FILE"), "{message}");
    assert!(!dir.join("untrusted.png").exists(), "an image was written");
    // Trusting the test CA, the image is the local folder's byte for byte.
    let ca_path = dir.join("ca.pem").display().to_string();
    let (https, out) = render(&dir, &url, "https.png", &[], &[("SSL_CERT_FILE", &ca_path)]);
    assert!(out.status.success(), "HTTPS render: {}", stderr(&out));
    assert!(https == local, "the image over HTTPS differs from the local folder's");
    // Plain HTTP to the TLS port is not silently accepted either.
    let (_, out) = render(&dir, &url.replacen("https", "http", 1), "plain.png", &["--retries", "0"], &[]);
    let message = stderr(&out);
    assert!(!out.status.success(), "plain HTTP to an HTTPS port succeeded");
    assert_eq!(message.trim().lines().count(), 1, "the server's error page was printed: {message}");
    assert!(message.contains("400 Bad Request"), "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bench_measures_a_store_over_http_as_from_its_folder() {
    let dir = scratch("remote_stores", "bench");
    import_ball(&dir, "www/ball.zarr");
    let server = nginx(&dir, &dir.join("www"));
    let url = format!("http://127.0.0.1:{}/ball.zarr", server.port);
    let quick = ["--size", "48", "--warm-frames", "2", "--path-frames", "3", "--budget-mb", "64"];
    let mut figures = Vec::new();
    for (source, json) in [("www/ball.zarr", "local.json"), (url.as_str(), "http.json")] {
        let out = voxstream(&[&["bench", "--scenes", source, "--json", json][..], &quick[..]].concat(), &dir);
        assert!(out.status.success(), "bench {source}: {}", stderr(&out));
        let text = std::fs::read_to_string(dir.join(json)).unwrap();
        let value: serde_json::Value = serde_json::from_str(&text).unwrap();
        let figure = value.as_array().and_then(|a| a.first()).cloned().expect("one source's figures");
        assert!(figure["scene"].as_str().is_some_and(|s| s.ends_with("ball.zarr")), "{figure}");
        assert!(figure["converged_ms"].as_f64().is_some_and(|ms| ms > 0.0), "{figure}");
        assert!(figure["bricks_resident"].as_u64().is_some_and(|b| b > 0), "{figure}");
        figures.push(figure);
    }
    // The store's own view: its warm frames take samples through the ball, several per pixel (an orbit framed
    // outside the store's place in the world once took a handful a frame and kept one brick).
    for figure in &figures {
        let per_frame =
            figure["samples_per_second"].as_f64().unwrap() * figure["warm_frame_ms"].as_f64().unwrap() / 1e3;
        assert!(per_frame > 4.0 * 48.0 * 48.0, "{per_frame} samples a warm frame: {figure}");
    }
    // The same view of the same data: the same converged work, wherever the bytes come from (interactive frames
    // never wait on the network, so their counts may differ).
    for field in ["converged_passes", "voxel_bytes"] {
        assert_eq!(figures[0][field], figures[1][field], "{field}: {} against {}", figures[0], figures[1]);
    }
    let log = std::fs::read_to_string(dir.join("nginx/access.log")).unwrap();
    assert!(log.lines().any(|l| l.starts_with("GET") && l.contains("/c/")), "bench fetched no brick: {log}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn faults_are_retried_and_the_image_stays_identical() {
    let dir = scratch("remote_stores", "faults");
    import_ball(&dir, "www/ball.zarr");
    let (local, _) = render(&dir, "www/ball.zarr", "local.png", &[], &[]);
    let server = nginx(&dir, &dir.join("www"));
    let log = dir.join("proxy.log");
    let faulty = proxy(server.port, &["--fail-rate", "0.2", "--truncate-rate", "0.05", "--seed", "7"], &log);
    let url = format!("http://127.0.0.1:{}/ball.zarr", faulty.port);
    let (image, out) = render(&dir, &url, "faults.png", &["--stats", "faults.json"], &[]);
    assert!(out.status.success(), "render through faults: {}", stderr(&out));
    assert!(image == local, "faults changed the image");
    let actions = std::fs::read_to_string(&log).unwrap();
    let count =
        |what: &str| actions.lines().filter(|l| l.split('\t').nth(2).is_some_and(|a| a.starts_with(what))).count();
    assert!(count("503") > 0 && count("truncated") > 0, "the proxy injected no faults:\n{actions}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_server_that_stops_answering_ends_the_run_with_one_line() {
    let dir = scratch("remote_stores", "stall");
    import_ball(&dir, "www/ball.zarr");
    let server = nginx(&dir, &dir.join("www"));
    // The metadata is read, then nothing more is answered.
    let stalled = proxy(server.port, &["--stall-after", "6"], &dir.join("proxy.log"));
    let url = format!("http://127.0.0.1:{}/ball.zarr", stalled.port);
    let mut child = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["render", &url, "--out", "stall.png", "--width", "64", "--height", "64", "--quiet"])
        .args(["--request-timeout", "1", "--retries", "1"])
        .current_dir(&dir)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("voxstream still waited on a stalled server after 120 s");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let output = child.wait_with_output().unwrap();
    let message = stderr(&output);
    assert!(!status.success(), "a run against a dead server succeeded: {message}");
    assert!(message.contains(&format!("127.0.0.1:{}", stalled.port)), "the message names no URL: {message}");
    assert!(!dir.join("stall.png").exists() || status.code() == Some(3), "an image was written as if complete");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn interactive_frames_never_wait_on_the_network() {
    let dir = scratch("remote_stores", "nonblocking");
    import_ball(&dir, "www/ball.zarr");
    let server = nginx(&dir, &dir.join("www"));
    // Metadata and per-brick ranges are answered, and the requests of the open: every shard's index (fetched
    // with the level probes) and one brick per level (the open checks that every level decodes); no brick after.
    let store = dir.join("www/ball.zarr");
    let mut shards = Vec::new();
    for level in ["0", "1", "2"] {
        shard_files(&store, &store.join(level), &mut shards);
    }
    let open_requests = (shards.len() + 3).to_string();
    let log = dir.join("proxy.log");
    let stalled =
        proxy(server.port, &["--stall-match", r"^/[^/]+/[0-9]+/c/", "--stall-match-after", &open_requests], &log);
    let url = format!("http://127.0.0.1:{}/ball.zarr", stalled.port);
    // A frame that waited for a brick would wait the request timeout, 100 s, at least.
    let mut child = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["render", &url, "--out", "frames.png", "--width", "64", "--height", "64", "--quiet"])
        .args(["--mode", "interactive", "--frames", "4", "--stats", "frames.json", "--request-timeout", "100"])
        .current_dir(&dir)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("interactive frames waited on bricks the server never sends");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let output = child.wait_with_output().unwrap();
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("frames.json")).unwrap())
        .unwrap_or_else(|e| panic!("no stats ({e}): {}", stderr(&output)));
    assert_eq!(stats["frame_ms"].as_array().map(Vec::len), Some(4), "{stats}");
    let stalls = std::fs::read_to_string(&log).unwrap().lines().filter(|l| l.contains("\tstall")).count();
    assert!(stalls > 0, "the frames asked for no brick, so nothing was shown about waiting");
    let total_bricks = 3 * 3 * 3 + 2 * 2 * 2 + 1;
    assert!(stats["bricks_resident"].as_u64().unwrap() < total_bricks, "{stats}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn missing_stores_and_credentials_in_urls_are_reported_without_secrets() {
    let dir = scratch("remote_stores", "missing");
    std::fs::create_dir_all(dir.join("www")).unwrap();
    let server = nginx(&dir, &dir.join("www"));
    let url = format!("http://alice:hunter2@127.0.0.1:{}/nothere.zarr?token=abc", server.port);
    let out = voxstream(&["info", &url], &dir);
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(message.contains(&format!("http://127.0.0.1:{}/nothere.zarr", server.port)), "{message}");
    assert!(!message.contains("hunter2") && !message.contains("token=abc"), "a secret was printed: {message}");
    assert_eq!(message.trim().lines().count(), 1, "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_disk_cache_makes_a_second_run_fetch_no_brick_and_survives_damage() {
    let dir = scratch("remote_stores", "cache");
    import_ball(&dir, "www/ball.zarr");
    let (local, _) = render(&dir, "www/ball.zarr", "local.png", &[], &[]);
    let server = nginx(&dir, &dir.join("www"));
    let url = format!("http://127.0.0.1:{}/ball.zarr", server.port);
    let cache = dir.join("cache");
    let flags = ["--cache-dir", cache.to_str().unwrap(), "--stats", "run.json"];
    let (first, out) = render(&dir, &url, "first.png", &flags, &[]);
    assert!(out.status.success() && first == local, "{}", stderr(&out));
    let chunk_gets = || {
        std::fs::read_to_string(dir.join("nginx/access.log"))
            .unwrap()
            .lines()
            .filter(|l| l.contains("GET") && l.contains("/c/"))
            .count()
    };
    let after_first = chunk_gets();
    assert!(after_first > 0);
    let (second, out) = render(&dir, &url, "second.png", &flags, &[]);
    assert!(out.status.success() && second == local, "{}", stderr(&out));
    assert_eq!(chunk_gets(), after_first, "the second run fetched bricks the cache held");
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("run.json")).unwrap()).unwrap();
    assert!(stats["remote"]["cache_hits"].as_u64().unwrap() > 0, "{}", stats["remote"]);
    // Damage every entry: each is detected, refetched, and the image is unchanged.
    let mut damaged = 0;
    for fan in std::fs::read_dir(&cache).unwrap().flatten() {
        for entry in std::fs::read_dir(fan.path()).unwrap().flatten() {
            let mut bytes = std::fs::read(entry.path()).unwrap();
            let middle = bytes.len() / 2;
            bytes[middle] ^= 0x40;
            std::fs::write(entry.path(), bytes).unwrap();
            damaged += 1;
        }
    }
    assert!(damaged > 0);
    let (third, out) = render(&dir, &url, "third.png", &flags, &[]);
    assert!(out.status.success() && third == local, "damaged cache entries changed the image: {}", stderr(&out));
    assert!(chunk_gets() > after_first, "damaged entries were not fetched again");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn other_tools_ome_zarr_over_http_reads_as_from_the_folder() {
    // zarr-python (pinned in data/venv) writes OME-Zarr 0.5 (Zarr v3, sharded) and 0.4 (Zarr v2) images.
    let dir = scratch("remote_stores", "foreign");
    let script = r#"
import sys, json, numpy as np, zarr
root = sys.argv[1]
z, y, x = np.mgrid[0:40, 0:48, 0:56].astype(np.float64)
data = (1000 * np.exp(-((x - 28) ** 2 + (y - 24) ** 2 + (z - 20) ** 2) / 200.0)).astype(np.uint16)
for version, name in ((3, "v3.zarr"), (2, "v2.zarr")):
    group = zarr.open_group(f"{root}/{name}", mode="w", zarr_format=version)
    datasets = []
    for level in range(2):
        level_data = data[:: 2 ** level, :: 2 ** level, :: 2 ** level]
        kwargs = dict(shards=(32, 32, 32)) if version == 3 else {}
        array = group.create_array(str(level), shape=level_data.shape, dtype="uint16", chunks=(16, 16, 16), **kwargs)
        array[...] = level_data
        datasets.append({"path": str(level), "coordinateTransformations": [{"type": "scale", "scale": [2.0 ** level] * 3}]})
    multiscales = [{"version": "0.4" if version == 2 else "0.5", "axes": [{"name": a, "type": "space"} for a in "zyx"], "datasets": datasets}]
    if version == 3:
        group.attrs["ome"] = {"version": "0.5", "multiscales": multiscales}
    else:
        group.attrs["multiscales"] = multiscales
"#;
    let status = Command::new(venv_python()).args(["-c", script, &dir.join("www").display().to_string()]).status();
    assert!(status.unwrap().success(), "zarr-python could not write the images");
    let server = nginx(&dir, &dir.join("www"));
    for name in ["v3.zarr", "v2.zarr"] {
        let (local, out) = render(&dir, &format!("www/{name}"), "local.png", &[], &[]);
        assert!(out.status.success(), "{name} local: {}", stderr(&out));
        let url = format!("http://127.0.0.1:{}/{name}", server.port);
        let (remote, out) = render(&dir, &url, "remote.png", &[], &[]);
        assert!(out.status.success(), "{name} over HTTP: {}", stderr(&out));
        assert!(remote == local, "{name}: the image over HTTP differs from the folder's");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_forged_shard_index_over_http_fails_its_bricks_and_fetches_no_forged_range() {
    // Fetching ahead reads shard indexes before zarrs checks them: forged entries (past 2^64, longer than a brick
    // can be, past the shard's end) must cost no request beyond a brick's bound, and the bricks fail as from disk.
    let dir = scratch("remote_stores", "forged_index");
    import_ball(&dir, "www/ball.zarr");
    let store = dir.join("www/ball.zarr");
    let level: serde_json::Value = serde_json::from_slice(&std::fs::read(store.join("0/zarr.json")).unwrap()).unwrap();
    let shape =
        |v: &serde_json::Value| -> Vec<u64> { v.as_array().unwrap().iter().map(|e| e.as_u64().unwrap()).collect() };
    let outer = shape(&level["chunk_grid"]["configuration"]["chunk_shape"]);
    let inner = shape(&level["codecs"][0]["configuration"]["chunk_shape"]);
    let count = outer.iter().zip(&inner).map(|(o, i)| o / i).product::<u64>() as usize;
    let mut forged = 0;
    for shard in ["0/c/1/0/0"] {
        let path = store.join(shard);
        let mut data = std::fs::read(&path).unwrap();
        let end = data.len() as u64;
        let start = data.len() - (16 * count + 4);
        for (k, entry) in data[start..start + 16 * count].chunks_exact_mut(16).enumerate() {
            if entry[..8] == [0xff; 8] {
                continue;
            }
            let (offset, length): (u64, u64) = match k % 3 {
                0 => (u64::MAX - 10, 100),
                1 => (0, 1 << 62),
                _ => (end + 1000, 500),
            };
            entry[..8].copy_from_slice(&offset.to_le_bytes());
            entry[8..].copy_from_slice(&length.to_le_bytes());
            forged += 1;
        }
        std::fs::write(&path, data).unwrap();
    }
    assert!(forged > 0, "no brick to forge");
    let server = nginx(&dir, &dir.join("www"));
    let url = format!("http://127.0.0.1:{}/ball.zarr", server.port);
    let started = Instant::now();
    let (_, out) = render(&dir, &url, "forged.png", &[], &[]);
    assert_eq!(out.status.code(), Some(3), "failed bricks exit 3: {}", stderr(&out));
    // The index's CRC32C no longer matches: zarrs refuses it, and the bricks fail as they would from disk.
    assert!(stderr(&out).contains("the shard is corrupt"), "{}", stderr(&out));
    assert!(started.elapsed() < Duration::from_secs(120), "the render took {:?}", started.elapsed());
    let log = std::fs::read_to_string(dir.join("nginx/access.log")).unwrap();
    for line in log.lines().filter(|l| l.contains("\"bytes=") && !l.contains("\"bytes=-")) {
        let range = line.split("\"bytes=").nth(1).unwrap().split('"').next().unwrap();
        let (first, last) = range.split_once('-').unwrap();
        let (first, last): (u64, u64) = (first.parse().unwrap(), last.parse().unwrap());
        assert!(last - first < 4 << 20 && first < u64::MAX - 100, "a forged range was fetched: {line}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
