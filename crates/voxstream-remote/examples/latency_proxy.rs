//! A TCP proxy that delays every byte by half a round trip each way, for the remote-store benchmarks
//! (`bench/remote.sh`, `bench/peers/tensorstore.sh`; issue 43): an emulated network between a client and a server
//! on this machine, where the kernel's `netem` is not at hand.
//!
//! ```sh
//! cargo run --release -p voxstream-remote --example latency_proxy -- LISTEN_PORT UPSTREAM_HOST:PORT RTT_MS
//! ```
//!
//! Why not `scripts/fault_proxy.py` (which the tests use for faults): it parses HTTP in Python and closes every
//! connection after one answer, so on this 2-core machine it spent about as much CPU as the client it served (a 2048³
//! render over it at 0 ms took 7.3 s against 4.0 s from nginx directly), and a client never paid for opening a
//! connection. Here bytes are copied as they come, connections stay open as long as the client keeps them (HTTP
//! keep-alive works as with a real server), and a new connection costs one round trip (the TCP handshake), as it
//! would across a real network. Bandwidth is not limited.

use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::time::Instant;

/// Copies `from` to `to`, each chunk written `delay` after it was read (in order; reading never waits on writing).
async fn delayed_copy(mut from: OwnedReadHalf, mut to: OwnedWriteHalf, delay: Duration) {
    let (send, mut receive) = mpsc::unbounded_channel::<(Instant, Vec<u8>)>();
    let writer = tokio::spawn(async move {
        while let Some((due, chunk)) = receive.recv().await {
            tokio::time::sleep_until(due).await;
            if to.write_all(&chunk).await.is_err() {
                return;
            }
        }
        let _ = to.shutdown().await;
    });
    let mut buffer = vec![0u8; 64 * 1024];
    loop {
        match from.read(&mut buffer).await {
            Ok(0) | Err(_) => break,
            Ok(n) => {
                if send.send((Instant::now() + delay, buffer[..n].to_vec())).is_err() {
                    break;
                }
            }
        }
    }
    drop(send);
    let _ = writer.await;
}

async fn serve(client: TcpStream, upstream: String, rtt: Duration) {
    // The handshake: a connection is usable one round trip after the client asked for it.
    tokio::time::sleep(rtt).await;
    let Ok(server) = TcpStream::connect(&upstream).await else { return };
    let _ = client.set_nodelay(true);
    let _ = server.set_nodelay(true);
    let (client_read, client_write) = client.into_split();
    let (server_read, server_write) = server.into_split();
    let half = rtt / 2;
    tokio::join!(delayed_copy(client_read, server_write, half), delayed_copy(server_read, client_write, half));
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(port), Some(upstream), Some(rtt)) = (args.first(), args.get(1), args.get(2)) else {
        eprintln!("usage: latency_proxy LISTEN_PORT UPSTREAM_HOST:PORT RTT_MS");
        std::process::exit(2);
    };
    let (Ok(port), Ok(rtt)) = (port.parse::<u16>(), rtt.parse::<f64>()) else {
        eprintln!("latency_proxy: LISTEN_PORT must be a port number and RTT_MS a number of milliseconds");
        std::process::exit(2);
    };
    let rtt = Duration::from_secs_f64(rtt.max(0.0) / 1000.0);
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_all().build();
    let Ok(runtime) = runtime else {
        eprintln!("latency_proxy: could not start the runtime");
        std::process::exit(1);
    };
    runtime.block_on(async move {
        let listener = match TcpListener::bind(("127.0.0.1", port)).await {
            Ok(listener) => listener,
            Err(e) => {
                eprintln!("latency_proxy: cannot listen on 127.0.0.1:{port}: {e}");
                std::process::exit(1);
            }
        };
        loop {
            if let Ok((client, _)) = listener.accept().await {
                tokio::spawn(serve(client, upstream.clone(), rtt));
            }
        }
    });
}
