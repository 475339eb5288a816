# Shared by the remote-store benchmarks (bench/remote.sh, bench/peers/tensorstore.sh); sourced, not run. Serves one
# store folder with nginx (byte ranges, ETags; every request logged as `REQUEST "RANGE" STATUS BYTES`) and puts a
# proxy in front of it that delays every answer (an emulated round trip).
# The caller sets `work` (a temporary folder it removes) and `pids` (an array), and kills "${pids[@]}" on exit.

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
wait_port() { for _ in $(seq 300); do (echo >/dev/tcp/127.0.0.1/"$1") 2>/dev/null && return 0; sleep 0.1; done; return 1; }

# serve_folder DIR: nginx serving DIR on a free port (printed in `nginx_port`); its log is $work/nginx/access.log.
serve_folder() {
    nginx_port=$(free_port)
    mkdir -p "$work/nginx"
    cat > "$work/nginx/nginx.conf" <<CONF
daemon off; master_process off; pid $work/nginx/nginx.pid; error_log $work/nginx/error.log;
events { worker_connections 1024; }
http { log_format ranges '\$request "\$http_range" \$status \$body_bytes_sent'; access_log $work/nginx/access.log ranges;
  client_body_temp_path $work/nginx/b; proxy_temp_path $work/nginx/p; fastcgi_temp_path $work/nginx/f;
  uwsgi_temp_path $work/nginx/u; scgi_temp_path $work/nginx/s;
  server { listen 127.0.0.1:$nginx_port; root $1; location / { } } }
CONF
    /usr/sbin/nginx -p "$work/nginx" -c "$work/nginx/nginx.conf" -e "$work/nginx/error.log" & pids+=($!)
    wait_port "$nginx_port"
}

# start_proxy RTT_MS: the delaying proxy in front of nginx on a free port (in `proxy_port`); it is the last of `pids`.
# By default the TCP proxy crates/voxstream-remote/examples/latency_proxy.rs (half the round trip each way, a round
# trip per new connection, keep-alive kept, next to no CPU); PROXY=python uses scripts/fault_proxy.py as the
# figures before 2026-12-08 did (it closes every connection after one answer and spends about as much CPU as the
# client on this 2-core machine, so its times are slower).
start_proxy() {
    proxy_port=$(free_port)
    if [ "${PROXY:-rust}" = python ]; then
        python3 scripts/fault_proxy.py --listen "$proxy_port" --upstream "127.0.0.1:$nginx_port" --latency-ms "$1" \
            >/dev/null 2>&1 & pids+=($!)
    else
        cargo build --release --quiet -p voxstream-remote --example latency_proxy
        target/release/examples/latency_proxy "$proxy_port" "127.0.0.1:$nginx_port" "$1" >/dev/null 2>&1 & pids+=($!)
    fi
    wait_port "$proxy_port"
}
