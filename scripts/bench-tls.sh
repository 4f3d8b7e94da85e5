#!/usr/bin/env bash
# HTTPS handshake cost: gridscada's rustls listener against Debian's nginx
# (OpenSSL) as the peer, same certificate (ECDSA P-256 from
# `gridscada cert self-signed`), same machine, same run.
#   bash scripts/bench-tls.sh [SECONDS]      (GRIDSCADA_BIN: default target/release/gridscada)
# Prints new TLS handshakes per second (`openssl s_time -new`) and the time of
# one HTTPS request on a new connection (curl, median of 200) for each.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${GRIDSCADA_BIN:-$root/target/release/gridscada}"
secs="${1:-5}"
PATH="$PATH:/usr/sbin:/sbin"
tmp=$(mktemp -d /tmp/gridscada-bench-tls.XXXXXX)
chmod 755 "$tmp"
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; rm -rf "$tmp"; }
trap cleanup EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
gs_port=$(free_port); ng_port=$(free_port)

"$bin" cert self-signed --host 127.0.0.1 --out "$tmp/certs" >/dev/null
mkdir -p "$tmp/plant"
cat > "$tmp/plant/gridscada.toml" <<TOML
tag_files = ["tags.toml"]
[server]
http = "127.0.0.1:$gs_port"
[server.tls]
cert = "$tmp/certs/cert.pem"
key = "$tmp/certs/key.pem"
TOML
cat > "$tmp/plant/tags.toml" <<'TOML'
[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:9"

[[tag]]
name = "A.V"
device = "D1"
kind = "input_register"
address = 0
type = "f32"
TOML
"$bin" serve --config "$tmp/plant/gridscada.toml" --data "$tmp/data" >"$tmp/serve.log" 2>&1 &
pids+=($!)
cat > "$tmp/nginx.conf" <<NGINX
worker_processes 1;
daemon off;
pid $tmp/nginx.pid;
error_log $tmp/nginx-error.log;
events { worker_connections 1024; }
http {
    access_log off;
    client_body_temp_path $tmp/b; proxy_temp_path $tmp/p; fastcgi_temp_path $tmp/f;
    uwsgi_temp_path $tmp/u; scgi_temp_path $tmp/s;
    server {
        listen 127.0.0.1:$ng_port ssl;
        ssl_certificate $tmp/certs/cert.pem;
        ssl_certificate_key $tmp/certs/key.pem;
        ssl_session_cache off;
        ssl_session_tickets off;
        location / { return 200 '{"status":"ok"}'; }
    }
}
NGINX
nginx -p "$tmp" -c "$tmp/nginx.conf" >/dev/null 2>&1 &
pids+=($!)
for _ in $(seq 100); do
    curl -fsS --cacert "$tmp/certs/cert.pem" "https://127.0.0.1:$gs_port/readyz" >/dev/null 2>&1 \
        && curl -fsS --cacert "$tmp/certs/cert.pem" "https://127.0.0.1:$ng_port/" >/dev/null 2>&1 && break
    sleep 0.2
done

measure() {
    local name=$1 port=$2 path=$3
    local n
    n=$(openssl s_time -connect "127.0.0.1:$port" -new -time "$secs" 2>/dev/null \
        | awk '/connections in [0-9.]+ real seconds/ {print $1; exit}')
    local median
    median=$(for _ in $(seq 200); do
        curl -so /dev/null --cacert "$tmp/certs/cert.pem" -w '%{time_total}\n' "https://127.0.0.1:$port$path"
    done | sort -n | awk '{a[NR]=$1} END {printf "%.2f", a[int(NR/2)]*1000}')
    printf '%-22s %8.0f handshakes/s   %6s ms per HTTPS request on a new connection (median of 200)\n' \
        "$name" "$(awk -v n="$n" -v s="$secs" 'BEGIN {print n / s}')" "$median"
}
echo "new TLS connections, $secs s each, $(nproc) cores, ECDSA P-256, TLS 1.3:"
measure "gridscada (rustls)" "$gs_port" /readyz
measure "nginx (OpenSSL) peer" "$ng_port" /
