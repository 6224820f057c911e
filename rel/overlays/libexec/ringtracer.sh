# The launcher's shared part, sourced by the checkout's bin/ringtracer and by
# a release's bin/ringtracer (docs/deploy.md). The sourcing script sets
#   here         the checkout, or the release's root (the server's socket is per folder)
#   caller       the folder the user called from (paths are theirs)
#   client       the thin client of `ringtracer serve`
#   build_stamp  a file no older than the build (a server started before it is stale)
# and defines
#   setup, build  what must be installed and built before a command (no-ops in a release)
#   erl_boot      sets erl_cmd: `erl` on the compiled application
# then calls `dispatch COMMAND ARGS...`.

export LANG=${LANG:-C.UTF-8} LC_ALL=${LC_ALL:-C.UTF-8}
# Schedulers that sleep when idle instead of spinning: with as many children as
# cores, a spinning scheduler takes the core a grandchild needs between two
# kernel calls (see docs/architecture.md, "Schedulers"). ERL_FLAGS
# reaches every VM started from here, peer nodes included; the user's own
# ERL_FLAGS come later and win.
# prevent_overlapping_partitions off: when the liveness watch disconnects a
# frozen node, OTP's global would otherwise have healthy nodes disconnect
# each other too (RingTracer registers no global names).
export ERL_FLAGS="+sbwt none +sbwtdcpu none +sbwtdio none -kernel prevent_overlapping_partitions false${ERL_FLAGS:+ $ERL_FLAGS}"

# Distribution runs over TLS with mutual authentication unless
# --insecure-plain says otherwise, and TLS is chosen when the VM boots. The
# folder is --tls DIR (or --tls=DIR) among the arguments; else, for a node
# that becomes distributed (a worker, a farm's head or client; a render with --nodes), the user's own
# (own_tls). tls_vm_flags makes the VM flags, file paths only, nothing
# secret, one array element each (a folder's name may hold spaces); they
# must stay those of RingTracer.Cluster.TLS.vm_args/1 (a test compares them).
tls_flags=()
find_tls() {
  local cmd=${1:-} dir="" prev="" a plain="" nodes="" help=""
  [ $# -gt 0 ] && shift
  for a in "$@"; do
    case "$a" in
      --tls=*) dir=${a#--tls=} ;;
      --insecure-plain) plain=1 ;;
      --nodes | --nodes=*) nodes=1 ;;
      --help | -h) help=1 ;;
    esac
    [ "$prev" = "--tls" ] && dir=$a
    prev=$a
  done
  if [ -n "$dir" ]; then
    dir=$(from_caller "$dir")
  elif [ -z "$plain$help" ] && { distributed "$cmd" || { [ "$cmd" = render ] && [ -n "$nodes" ]; }; }; then
    dir=$(own_tls) || exit 1
  else
    return 0
  fi
  tls_vm_flags "$dir"
}

# Commands whose node is always distributed: a worker, and a farm's head
# and clients.
distributed() {
  case "$1" in
    worker | farm | submit | jobs | status | wait | cancel | fetch) return 0 ;;
    *) return 1 ;;
  esac
}

tls_vm_flags() {
  local d=$1 side
  tls_flags=(-proto_dist inet_tls -ssl_dist_opt)
  for side in server client; do
    tls_flags+=("${side}_certfile" "$d/node.pem" "${side}_keyfile" "$d/node.key"
      "${side}_cacertfile" "$d/ca.pem" "${side}_verify" verify_peer
      "${side}_secure_renegotiate" true "${side}_depth" 2)
    if [ "$side" = server ]; then tls_flags+=(server_fail_if_no_peer_cert true); fi
  done
}

# The user's own TLS folder, ${XDG_CONFIG_HOME:-~/.config}/ringtracer/tls,
# made on first use: a private CA signs one node certificate (localhost,
# 127.0.0.1, ::1 and this host's name) and its key is thrown away, so
# nothing else can ever be signed by it. Everything is made in a new
# folder of a fresh name (mktemp -d: mode 0700 from the start, keys under
# umask 077), then renamed into place in one step; of two launchers that
# race, the first rename wins and the other's folder is removed. Prints
# the folder.
own_tls() {
  local parent dir tmp log
  parent=${XDG_CONFIG_HOME:-$HOME/.config}/ringtracer
  dir=$parent/tls
  if [ -e "$dir" ] || [ -L "$dir" ]; then
    printf '%s' "$dir"
    return 0
  fi
  command -v openssl >/dev/null || {
    echo "ringtracer: openssl is needed to make your TLS certificates (apt-get install openssl), or give --tls DIR" >&2
    return 1
  }
  (umask 077 && mkdir -p -- "$parent") || return 1
  if [ "$(stat -c %u -- "$parent")" != "$(id -u)" ] || (( 8#$(stat -c %a -- "$parent") & 8#022 )); then
    echo "ringtracer: $parent must be yours and writable by you only (it will hold your TLS key)" >&2
    return 1
  fi
  tmp=$(mktemp -d -- "$parent/.tls.XXXXXXXX") || return 1
  if ! log=$(make_own_tls "$tmp" 2>&1); then
    rm -rf -- "$tmp"
    echo "ringtracer: could not make your TLS certificates in $dir: $log" >&2
    return 1
  fi
  mv -T -- "$tmp" "$dir" 2>/dev/null || rm -rf -- "$tmp"
  echo "ringtracer: made your own TLS certificates in $dir (distribution runs over TLS with them)" >&2
  printf '%s' "$dir"
}

make_own_tls() {
  local d=$1 host san="DNS:localhost,IP:127.0.0.1,IP:::1"
  host=$(hostname 2>/dev/null || :)
  valid_host "$host" && [ "$host" != localhost ] && san="$san,DNS:$host"
  umask 077
  new_ca "$d" "/CN=RingTracer private CA of uid $(id -u)" &&
    sign_node "$d" "$d" localhost "$san" 3650 &&
    rm -f -- "$d/ca.key" "$d/node.csr" &&
    chmod 644 -- "$d/ca.pem" "$d/node.pem"
}

# A CA in folder $1 (ca.key, ca.pem), named $2; under the caller's umask.
new_ca() {
  openssl req -x509 -new -nodes -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 \
    -keyout "$1/ca.key" -out "$1/ca.pem" -days 3650 -subj "$2"
}

# A node's key and certificate in folder $2 (node.key, node.pem; node.csr
# left for the caller to remove), signed by the CA in folder $1: common
# name $3, subject alternative names $4, valid $5 days.
sign_node() {
  openssl req -new -nodes -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 \
    -keyout "$2/node.key" -out "$2/node.csr" -subj "/CN=$3" &&
    openssl x509 -req -in "$2/node.csr" -CA "$1/ca.pem" -CAkey "$1/ca.key" \
      -set_serial "0x$(openssl rand -hex 16)" -out "$2/node.pem" -days "$5" \
      -extfile <(printf '%s\n' "subjectAltName=$4" "basicConstraints=CA:FALSE" \
        "keyUsage=digitalSignature" "extendedKeyUsage=serverAuth,clientAuth")
}

# A host name (letters, digits, -, dots between labels) or an IP address.
valid_host() {
  [[ $1 =~ ^[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*$ ]] ||
    [[ $1 =~ ^[0-9]{1,3}(\.[0-9]{1,3}){3}$ ]] || [[ $1 =~ ^[0-9A-Fa-f:.]+$ && $1 == *:* ]]
}

# Whether process $1 runs (not ended, nor a zombie) and catches SIGUSR2
# (bit 11 of SigCgt in /proc): a VM does once RingTracer.CLI.Signals is in
# place, the client once it has sent its command.
proc_field() {
  local key value
  while read -r key value; do
    [ "$key" = "$2:" ] && { printf '%s' "$value"; return 0; }
  done < "/proc/$1/status" 2>/dev/null
  return 1
}
running() { local s; s=$(proc_field "$1" State) && [ "${s%% *}" != Z ]; }
catches_usr2() { local m; m=$(proc_field "$1" SigCgt) && (( (16#$m >> 11) & 1 )); }

# Runs "$@" in the background, staying its parent, and sets `status` to its
# exit status:
# the first SIGINT becomes SIGUSR2 (which the VM, booted with Ctrl-C's break
# menu off, and the client take as "cancel and exit 130"), a second one
# SIGKILL; SIGTERM is passed on. An interrupt is held until the process
# catches SIGUSR2: during a VM's boot SIGUSR2 would kill it and SIGTERM
# would stop it with status 0, as if it had done its work. A process that
# ends while one is held was interrupted before it could act: 130 or 143.
supervise() {
  local pid="" interrupted="" held=""
  status=0
  trap 'if [ -n "$interrupted" ]; then kill -KILL "$pid" 2>/dev/null; else interrupted=1; held="${held:-USR2}"; fi' INT
  trap 'held=TERM' TERM
  "$@" &
  pid=$!
  while :; do
    if [ -n "$held" ]; then
      if catches_usr2 "$pid"; then
        kill -"$held" "$pid" 2>/dev/null
        held=""
      elif running "$pid"; then
        sleep 0.02
        continue
      else
        wait "$pid" 2>/dev/null || :
        if [ "$held" = TERM ]; then status=143; else status=130; fi
        echo "ringtracer: $([ $status = 130 ] && echo interrupted || echo terminated); nothing written" >&2
        break
      fi
    fi
    status=0
    wait "$pid" || status=$?
    kill -0 "$pid" 2>/dev/null || break
  done
  trap - INT TERM
}

# Runs a command of RingTracer.CLI in a VM of its own, from the caller's
# folder.
run_cli() {
  build
  erl_boot
  find_tls "$@"
  # A farm's client is a hidden node: it connects to the head alone, and
  # the farm's other nodes (OTP's global) never try to reach it.
  local hidden=()
  case "${1:-}" in submit | jobs | status | wait | cancel | fetch) hidden=(-hidden) ;; esac
  cd "$caller"
  supervise "${erl_cmd[@]}" ${tls_flags[@]+"${tls_flags[@]}"} ${hidden[@]+"${hidden[@]}"} \
    -s Elixir.RingTracer.CLI main -extra "$@"
  exit "$status"
}

# The resident render node's socket (`ringtracer serve`), one per checkout or release.
socket_path() {
  if [ -n "${RINGTRACER_SOCKET:-}" ]; then
    from_caller "$RINGTRACER_SOCKET"
  else
    printf '%s/ringtracer/serve-%s.sock' "${XDG_RUNTIME_DIR:-$HOME/.cache}" "$(printf %s "$here" | cksum | cut -d' ' -f1)"
  fi
}

# A render through the running server, if there is one of this build: the
# client exits 200, having written nothing, when there is none or when the
# command needs a VM of its own (a render on other nodes).
# RINGTRACER_SERVER: auto (the default), off (never), only (fail without one).
via_server() {
  build
  local use=${RINGTRACER_SERVER:-auto} sock
  case "$use" in
    off) return 0 ;;
    auto | only) ;;
    *) echo "ringtracer: RINGTRACER_SERVER takes auto, off or only, got: $use" >&2; exit 2 ;;
  esac
  sock=$(socket_path)
  if [ ! -S "$sock" ] || [ ! -x "$client" ]; then
    [ "$use" = only ] && { echo "ringtracer: no server on $sock (start one with: ringtracer serve)" >&2; exit 1; }
    return 0
  fi
  if [ "$build_stamp" -nt "$sock" ]; then
    echo "ringtracer: the server on $sock runs an older build (restart ringtracer serve)" >&2
    [ "$use" = only ] && exit 1
    return 0
  fi
  supervise "$client" "$sock" "$@"
  [ "$status" -eq 200 ] || exit "$status"
  if [ "$use" = only ]; then
    echo "ringtracer: the server on $sock cannot take this command (a render on other nodes boots a VM of its own)" >&2
    exit 1
  fi
}

# A path given by the user, against the folder they called us from.
from_caller() { case "$1" in /*) printf '%s' "$1" ;; *) printf '%s' "$caller/$1" ;; esac; }

# A certificate authority, and node certificates signed by it (Debian's
# openssl). A folder is made with its final mode in one step (mkdir -m 700);
# one that exists already must be the caller's and closed to others, and is
# never chmod-ed by name. openssl's own words are shown when it fails.
tls() {
  command -v openssl >/dev/null || { echo "openssl not found: apt-get install openssl" >&2; exit 1; }
  local what=${1:-} log
  case "$what" in
    ca)
      local dir
      dir=$(from_caller "${2:?usage: ringtracer tls ca CA_DIR}")
      [ -e "$dir/ca.key" ] && { echo "ringtracer tls ca: $dir/ca.key exists already; not replacing a CA" >&2; exit 1; }
      private_dir "$dir"
      log=$(umask 077 && new_ca "$dir" "/CN=RingTracer cluster CA" 2>&1) ||
        { echo "ringtracer tls ca: openssl failed: $log" >&2; exit 1; }
      echo "wrote $dir/ca.pem and $dir/ca.key (keep ca.key off the nodes)"
      ;;
    node)
      local ca out
      ca=$(from_caller "${2:?usage: ringtracer tls node CA_DIR OUT_DIR [HOST...]}")
      out=$(from_caller "${3:?usage: ringtracer tls node CA_DIR OUT_DIR [HOST...]}")
      shift 3
      local hosts=("$@")
      [ ${#hosts[@]} -gt 0 ] || hosts=("$(hostname -s)")
      local san="DNS:localhost,IP:127.0.0.1" h
      for h in "${hosts[@]}"; do
        valid_host "$h" || { echo "ringtracer tls node: not a host name or an IP address: '$h'" >&2; exit 2; }
        if [[ $h =~ ^[0-9.]+$ || $h == *:* ]]; then san="$san,IP:$h"; else san="$san,DNS:$h"; fi
      done
      for h in ca.pem ca.key; do
        [ -f "$ca/$h" ] || { echo "ringtracer tls node: $ca/$h not found (make a CA with: ringtracer tls ca $ca)" >&2; exit 1; }
      done
      private_dir "$out"
      log=$( (umask 077 && sign_node "$ca" "$out" "${hosts[0]}" "$san" 825 &&
        cp "$ca/ca.pem" "$out/ca.pem" && chmod 644 "$out/node.pem" "$out/ca.pem") 2>&1) ||
        { rm -f -- "$out/node.csr"; echo "ringtracer tls node: openssl failed: $log" >&2; exit 1; }
      rm -f -- "$out/node.csr"
      echo "wrote $out/{ca.pem,node.pem,node.key} for ${hosts[*]}; copy the folder to that node and give --tls $out"
      ;;
    args)
      # The VM flags for a TLS folder, each followed by a NUL (for tests).
      tls_vm_flags "$(from_caller "${2:?usage: ringtracer tls args DIR}")"
      printf '%s\0' "${tls_flags[@]}"
      ;;
    *) echo "usage: ringtracer tls ca CA_DIR | ringtracer tls node CA_DIR OUT_DIR [HOST...]" >&2; exit 2 ;;
  esac
}

# A folder for keys: made mode 0700 in one step, or, when it exists, one
# of the caller's own that no one else can enter.
private_dir() {
  local d=$1
  mkdir -p -- "$(dirname -- "$d")"
  mkdir -m 700 -- "$d" 2>/dev/null && return 0
  if [ -L "$d" ] || [ ! -d "$d" ] || [ "$(stat -c %u -- "$d")" != "$(id -u)" ] || (( 8#$(stat -c %a -- "$d") & 8#077 )); then
    echo "ringtracer tls: $d must be a folder of yours that only you can enter (chmod 700 $d), or not exist" >&2
    exit 1
  fi
}

# The application's version, from its .app file in folder $1.
app_version() {
  sed -n 's/.*{vsn, *"\([^"]*\)"}.*/\1/p' "$1/ring_tracer.app" | head -n 1
}

# The commands common to the checkout and a release.
dispatch() {
  local cmd=${1:-}
  [ $# -gt 0 ] && shift
  case "$cmd" in
    render) setup; via_server render "$@"; run_cli render "$@" ;;
    serve) setup; RINGTRACER_SOCKET=$(socket_path) run_cli serve "$@" ;;
    worker|cookie|farm|submit|jobs|status|wait|cancel|fetch) setup; run_cli "$cmd" "$@" ;;
    tls) tls "$@" ;;
    # Help, and unknown commands (with a suggestion), from RingTracer.CLI.
    "") setup; run_cli ;;
    *) setup; run_cli "$cmd" "$@" ;;
  esac
}
