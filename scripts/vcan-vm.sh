#!/usr/bin/env bash
# vcan-vm.sh: run commands against a real SocketCAN vcan0 (and vcan1), in a small qemu VM when
# this host's kernel has no SocketCAN, directly on the host when it has vcan.
#
#   scripts/vcan-vm.sh run [OPTIONS] -- CMD [ARGS...]
#   scripts/vcan-vm.sh run-tests [OPTIONS] BINARY... [-- TEST_ARGS...]
#   scripts/vcan-vm.sh cargo-test [OPTIONS] [CARGO_ARGS...] [-- TEST_ARGS...]
#   scripts/vcan-vm.sh runner BINARY [ARGS...]      (as CARGO_TARGET_<TRIPLE>_RUNNER)
#   scripts/vcan-vm.sh setup | clean | help
#
# The VM: Debian's own kernel package (found with `apt-cache depends linux-image-amd64`) booted
# under qemu TCG with an initramfs of busybox static, the CAN kernel modules, can-utils, the given
# binaries and their shared libraries. docs/vcan-vm.md explains it all, with measured times.
#
# Exit code: the command's own (with several, the first non-zero one); 124 when a command or the
# VM ran out of time; 125 when the VM itself failed (install, boot, vcan setup, panic, lost
# result); 2 for a usage error.
set -euo pipefail

SCRIPT_PATH=$(readlink -f "${BASH_SOURCE[0]}")
SCRIPT_DIR=$(dirname "$SCRIPT_PATH")
HELPERS=$SCRIPT_DIR/vcan-vm
REPO_ROOT=$(dirname "$SCRIPT_DIR")
CACHE=${VCAN_VM_CACHE:-$REPO_ROOT/target/vcan-vm}

# Modules loaded in the VM, in this order after their dependencies (modinfo depends= is followed).
# can, can-raw, can-dev and vcan are the core; the rest are small and make BCM, ISO-TP, cangw and
# vxcan tests possible.
MODULES=(can can-raw can-bcm can-gw can-isotp can-dev vcan vxcan)
# can-utils programs copied into the VM.
CAN_UTILS=(candump cansend cangen canplayer canbusload cangw isotpsend isotprecv)
# Host environment variables passed into the VM when set (plus every PETREL_* variable, and the
# names listed in VCAN_VM_PASS_ENV).
PASS_ENV=(RUST_BACKTRACE RUST_LIB_BACKTRACE RUST_LOG RUST_TEST_THREADS RUST_TEST_NOCAPTURE
    RUST_MIN_STACK NO_COLOR)

EXIT_TIMEOUT=124
EXIT_BENCH=125
EXIT_USAGE=2

log() { printf 'vcan-vm: %s\n' "$*" >&2; }
die() {
    printf 'vcan-vm: error: %s\n' "$*" >&2
    exit "$EXIT_BENCH"
}
usage_error() {
    printf 'vcan-vm: %s\n(see: %s help)\n' "$*" "$0" >&2
    exit "$EXIT_USAGE"
}
now_ms() { date +%s%3N; }
ms_as_s() { printf '%d.%03d' $(($1 / 1000)) $(($1 % 1000)); }
secs_since() { ms_as_s $(($(now_ms) - $1)); } # secs_since START_MS -> "1.234"

usage() {
    cat <<EOF
Usage:
  $0 run [OPTIONS] -- CMD [ARGS...]
      Run one command where vcan0 and vcan1 exist. In the VM, CMD runs under busybox: its
      applets, candump, cansend, cangen, canplayer, ... are there (busybox sh runs its own applets
      before PATH: iproute2's full ip is /usr/sbin/ip). A CMD given as a path, or found on the
      host PATH but not in the VM, is copied in with its shared libraries.
  $0 run-tests [OPTIONS] BINARY... [-- TEST_ARGS...]
      Copy each binary (a cargo test executable, say) into the VM at its host path, with its
      shared libraries, and run each in turn with TEST_ARGS.
  $0 cargo-test [OPTIONS] [CARGO_ARGS...] [-- TEST_ARGS...]
      Build with 'cargo test --no-run CARGO_ARGS' and run every test executable it reports, as
      cargo would (in its package's folder, which is copied into the VM without target/).
      Example: $0 cargo-test -p petrel-can-bridge --test socketcan -- --include-ignored
  $0 runner BINARY [ARGS...]
      For CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUNNER: run one binary like run-tests, in the
      current folder's path, with cargo's CARGO_MANIFEST_DIR/CARGO_PKG_* variables. Options come
      from the VCAN_VM_* variables only.
  $0 setup      Install what the VM needs, fetch the kernel, build the cached initramfs base.
  $0 clean      Remove the cache ($CACHE).

Options (and the environment variable that sets each default):
  --timeout SECONDS  limit for each command [VCAN_VM_TIMEOUT, 300]
  --include PATH     also copy PATH (file or folder) into the VM at the same path; an ELF file
                     given this way brings its shared libraries [VCAN_VM_INCLUDE, colon-separated]
  --env NAME=VALUE   set a variable for the commands (repeatable)
  --cwd DIR          working folder of the commands [VCAN_VM_CWD; / in the VM, \$PWD on the host]
  --ifaces LIST      vcan interfaces to create, comma-separated [VCAN_VM_IFACES, vcan0,vcan1]
  --vm | --host      force the VM, or require the host's own vcan [VCAN_VM_MODE=auto|vm|host]
  --smp N            VM CPUs [VCAN_VM_SMP, 2]
  --memory MB        VM memory, raised for big binaries [VCAN_VM_MEMORY, 1024]
Other settings: VCAN_VM_BOOT_TIMEOUT (seconds the VM may take beyond the commands' limits, 240),
VCAN_VM_KERNEL_PKG (a linux-image-* package instead of the one linux-image-amd64 names),
VCAN_VM_CACHE (cache folder), VCAN_VM_QUIET=1 (print only the commands' output and results),
VCAN_VM_PASS_ENV (more host variable names to pass in; RUST_BACKTRACE, RUST_LOG, RUST_TEST_*,
NO_COLOR and PETREL_* always are), VCAN_VM_FAST=0 (boot the bzImage with SeaBIOS, the slow way),
VCAN_VM_APPEND (more kernel command line).
The commands see VCAN_BENCH=vm or host, and VCAN_IFACES="vcan0 vcan1".

Exit code: the command's (the first non-zero of several); 124 on timeout; 125 when the VM
failed; 2 on a usage error.
EOF
}

# ---------------------------------------------------------------------------------------------
# Settings

TIMEOUT=${VCAN_VM_TIMEOUT:-300}
IFACES=${VCAN_VM_IFACES:-vcan0,vcan1}
MODE=${VCAN_VM_MODE:-auto}
SMP=${VCAN_VM_SMP:-2}
MEMORY=${VCAN_VM_MEMORY:-1024}
BOOT_TIMEOUT=${VCAN_VM_BOOT_TIMEOUT:-240}
QUIET=${VCAN_VM_QUIET:-0}
INCLUDES=()
ENVS=()
if [ -n "${VCAN_VM_INCLUDE:-}" ]; then
    IFS=: read -r -a INCLUDES <<<"$VCAN_VM_INCLUDE"
fi

is_uint() { [[ $1 =~ ^[0-9]+$ ]]; }
# uint_at_least VALUE MIN: VALUE is a whole number >= MIN.
uint_at_least() { is_uint "$1" && [ "$1" -ge "$2" ]; }

# parse_option ARGS...: consumes one option (and its value) from the front; sets SHIFT_BY.
parse_option() {
    local opt=$1 val=${2-}
    SHIFT_BY=2
    case $opt in
    --timeout | --include | --env | --cwd | --ifaces | --smp | --memory)
        [ $# -ge 2 ] || usage_error "$opt needs a value"
        ;;
    esac
    case $opt in
    --timeout) uint_at_least "$val" 1 || usage_error "--timeout wants whole seconds > 0, not '$val'"
        TIMEOUT=$val ;;
    --include) INCLUDES+=("$val") ;;
    --env) [[ $val =~ ^[A-Za-z_][A-Za-z0-9_]*= ]] || usage_error "--env wants NAME=VALUE, not '$val'"
        ENVS+=("$val") ;;
    --cwd) [[ $val == /* ]] || usage_error "--cwd wants an absolute path, not '$val'"
        CWD_OPT=$val ;;
    --ifaces) IFACES=$val ;;
    --smp) uint_at_least "$val" 1 || usage_error "--smp wants a count, not '$val'"
        SMP=$val ;;
    --memory) uint_at_least "$val" 128 || usage_error "--memory wants megabytes >= 128, not '$val'"
        MEMORY=$val ;;
    --vm) MODE=vm; SHIFT_BY=1 ;;
    --host) MODE=host; SHIFT_BY=1 ;;
    *) usage_error "unknown option '$opt'" ;;
    esac
}

check_settings() {
    uint_at_least "$TIMEOUT" 1 || usage_error "VCAN_VM_TIMEOUT wants whole seconds > 0, not '$TIMEOUT'"
    is_uint "$BOOT_TIMEOUT" || usage_error "VCAN_VM_BOOT_TIMEOUT wants whole seconds, not '$BOOT_TIMEOUT'"
    uint_at_least "$SMP" 1 || usage_error "VCAN_VM_SMP wants a count, not '$SMP'"
    is_uint "$MEMORY" || usage_error "VCAN_VM_MEMORY wants megabytes, not '$MEMORY'"
    case $MODE in auto | vm | host) ;; *) usage_error "VCAN_VM_MODE is auto, vm or host, not '$MODE'" ;; esac
    [[ $IFACES =~ ^[A-Za-z0-9_.-]+(,[A-Za-z0-9_.-]+)*$ ]] || usage_error "--ifaces wants names separated by commas, not '$IFACES'"
    [[ -z $CWD_OPT || $CWD_OPT == /* ]] || usage_error "VCAN_VM_CWD wants an absolute path, not '$CWD_OPT'"
}

# ---------------------------------------------------------------------------------------------
# Installing what is missing (Debian packages), quietly and only once.

APT_UPDATED=0
apt_update() {
    [ "$APT_UPDATED" = 1 ] && return 0
    local t0
    t0=$(now_ms)
    log "apt-get update"
    apt-get update -qq -o DPkg::Lock::Timeout=300 >"$CACHE/apt.log" 2>&1 || {
        tail -n 20 "$CACHE/apt.log" >&2
        die "apt-get update failed (log: $CACHE/apt.log)"
    }
    APT_UPDATED=1
    log "apt-get update done in $(secs_since "$t0") s"
}

apt_install() {
    [ "$(id -u)" = 0 ] || die "missing Debian packages: $*. Install them as root: apt-get install --no-install-recommends $*"
    local t0
    t0=$(now_ms)
    log "installing $* (apt-get)"
    # Wait for another apt (a test script installing its own packages, say) rather than fail.
    local apt_cmd=(apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=300 "$@")
    if ! DEBIAN_FRONTEND=noninteractive "${apt_cmd[@]}" >"$CACHE/apt.log" 2>&1; then
        # The package lists may be missing or stale on a fresh machine.
        apt_update
        DEBIAN_FRONTEND=noninteractive "${apt_cmd[@]}" >"$CACHE/apt.log" 2>&1 || {
            tail -n 20 "$CACHE/apt.log" >&2
            die "apt-get install $* failed (log: $CACHE/apt.log)"
        }
    fi
    log "installed in $(secs_since "$t0") s"
}

# ensure_tools vm|host: the Debian packages each mode needs.
ensure_tools() {
    local missing=()
    command -v candump >/dev/null 2>&1 || missing+=(can-utils)
    if [ "$1" = vm ]; then
        command -v qemu-system-x86_64 >/dev/null 2>&1 || missing+=(qemu-system-x86)
        [ -x /bin/busybox ] || missing+=(busybox-static)
        command -v cpio >/dev/null 2>&1 || missing+=(cpio)
    fi
    if [ "${#missing[@]}" -gt 0 ]; then
        apt_install "${missing[@]}"
    fi
    return 0
}

# ---------------------------------------------------------------------------------------------
# The kernel: Debian's package, unpacked once; only vmlinuz and the CAN modules are kept.

ko_cat() { # ko_cat FILE: the module, uncompressed, on stdout
    case $1 in
    *.ko) cat "$1" ;;
    *.ko.xz) xz -dc "$1" ;;
    *.ko.zst) zstd -qdc "$1" ;;
    *.ko.gz) gzip -dc "$1" ;;
    *) die "unknown module format: $1" ;;
    esac
}

ko_depends() { # ko_depends FILE: the names in its modinfo depends= field, one per line
    ko_cat "$1" | tr '\0' '\n' | sed -n 's/^depends=//p' | tr ',' '\n' | sed '/^$/d'
}

kernel_pkg_from_apt() {
    apt-cache depends linux-image-amd64 2>/dev/null |
        awk '$1 == "Depends:" && $2 ~ /^linux-image-[0-9]/ { print $2; exit }' || true
}

# ensure_kernel: sets KDIR to a complete cached kernel folder.
ensure_kernel() {
    local pkg=${VCAN_VM_KERNEL_PKG:-} d
    if [ -z "$pkg" ]; then
        # Any complete cached kernel will do (the newest): no apt look-up on a warm cache.
        d=$(find "$CACHE/kernel" -mindepth 2 -maxdepth 2 -name complete -path '*/linux-image-*' \
            -printf '%h\n' 2>/dev/null | sort -V | tail -n 1 || true)
        if [ -n "$d" ]; then
            KDIR=$d
            return 0
        fi
        pkg=$(kernel_pkg_from_apt)
        if [ -z "$pkg" ]; then
            apt_update
            pkg=$(kernel_pkg_from_apt)
        fi
        [ -n "$pkg" ] || die "apt-cache depends linux-image-amd64 names no linux-image-N package; set VCAN_VM_KERNEL_PKG"
    fi
    [[ $pkg =~ ^linux-image-[A-Za-z0-9.+~-]+$ ]] || die "VCAN_VM_KERNEL_PKG '$pkg' is not a linux-image-* package name"
    KDIR=$CACHE/kernel/$pkg
    [ -f "$KDIR/complete" ] && return 0

    local t0 tmp deb x rel
    t0=$(now_ms)
    log "fetching kernel package $pkg (about 70 MB; once, cached in $KDIR)"
    tmp=$(mktemp -d "$CACHE/tmp.kernel.XXXXXX")
    TMP_DIRS+=("$tmp")
    # As root, apt would hand the download to its _apt user, who may not write here.
    local dl=(apt-get download -qq)
    [ "$(id -u)" = 0 ] && dl+=(-o APT::Sandbox::User=root)
    if ! (cd "$tmp" && "${dl[@]}" "$pkg") >"$CACHE/apt.log" 2>&1; then
        # Stale package lists: the mirror may have moved on to the next kernel ABI.
        apt_update
        if [ -z "${VCAN_VM_KERNEL_PKG:-}" ]; then
            pkg=$(kernel_pkg_from_apt)
            [ -n "$pkg" ] || die "apt-cache depends linux-image-amd64 names no linux-image-N package"
            KDIR=$CACHE/kernel/$pkg
        fi
        (cd "$tmp" && "${dl[@]}" "$pkg") >"$CACHE/apt.log" 2>&1 || {
            tail -n 20 "$CACHE/apt.log" >&2
            die "apt-get download $pkg failed (log: $CACHE/apt.log)"
        }
    fi
    deb=$(find "$tmp" -maxdepth 1 -name "${pkg}_*.deb" -print -quit)
    [ -n "$deb" ] || die "apt-get download $pkg produced no .deb"
    x=$tmp/x
    dpkg-deb -x "$deb" "$x"
    rel=$(find "$x/lib/modules" -mindepth 1 -maxdepth 1 -type d -printf '%f\n' | head -n 1)
    [ -n "$rel" ] || die "$pkg has no lib/modules/VERSION folder"
    [ -f "$x/boot/vmlinuz-$rel" ] || die "$pkg has no boot/vmlinuz-$rel"

    # Every module of the package by name (both - and _ spellings), then the closure of
    # MODULES over depends=, dependencies first.
    local -A path_of=() seen=()
    local f n order=()
    while IFS= read -r f; do
        n=${f##*/}
        n=${n%%.ko*}
        path_of[$n]=$f
        path_of[${n//_/-}]=$f
        path_of[${n//-/_}]=$f
    done < <(find "$x/lib/modules/$rel" -name '*.ko*')
    visit() {
        local name=$1 dep deps
        [ -n "${seen[$name]:-}" ] && return 0
        seen[$name]=1
        [ -n "${path_of[$name]:-}" ] || die "$pkg has no module '$name' (needed for vcan)"
        deps=$(ko_depends "${path_of[$name]}")
        for dep in $deps; do
            visit "$dep"
        done
        order+=("$name")
    }
    for n in "${MODULES[@]}"; do
        visit "$n"
    done

    local stage=$tmp/stage
    mkdir -p "$stage/modules"
    cp "$x/boot/vmlinuz-$rel" "$stage/vmlinuz"
    cp "$x/boot/config-$rel" "$stage/config" 2>/dev/null || true
    : >"$stage/modules.order"
    for n in "${order[@]}"; do
        f=${path_of[$n]}
        n=${f##*/}
        n=${n%%.ko*}.ko
        ko_cat "$f" >"$stage/modules/$n"
        echo "$n" >>"$stage/modules.order"
    done
    echo "$rel" >"$stage/release"
    dpkg-deb -f "$deb" Package Version >"$stage/package"
    rm -rf "$KDIR"
    mkdir -p "$CACHE/kernel"
    mv "$stage" "$KDIR"
    touch "$KDIR/complete"
    rm -rf "$tmp"
    log "kernel $rel ready in $(secs_since "$t0") s (modules: ${order[*]})"
}

# ensure_vmlinux: the uncompressed kernel, for a direct PVH boot: qemu loads the ELF and jumps
# to its PVH entry, which skips the bzImage decompressor (about 3 s under TCG). Writes
# KDIR/vmlinux, or KDIR/vmlinux.none when this kernel cannot be booted that way.
ensure_vmlinux() {
    [ -f "$KDIR/vmlinux" ] || [ -f "$KDIR/vmlinux.none" ] && return 0
    local magic off out=$KDIR/vmlinux.part t0
    t0=$(now_ms)
    for magic in '\xfd7zXZ\x00:xz -dcq --single-stream' '\x28\xb5\x2f\xfd:zstd -qdc' '\x1f\x8b\x08:gzip -dcq'; do
        off=$(LC_ALL=C grep -obUaP -m 1 "${magic%%:*}" "$KDIR/vmlinuz" 2>/dev/null | head -n 1 | cut -d: -f1 || true)
        [ -n "$off" ] || continue
        # Decompressors complain about the bytes after the stream: judge by the result.
        tail -c +$((off + 1)) "$KDIR/vmlinuz" | ${magic#*:} >"$out" 2>/dev/null || true
        if is_elf "$out" && command -v readelf >/dev/null 2>&1 &&
            LC_ALL=C readelf -n "$out" 2>/dev/null | grep -q 'Xen.*0x00000012'; then
            mv "$out" "$KDIR/vmlinux"
            log "uncompressed vmlinux for a direct (PVH) boot in $(secs_since "$t0") s"
            return 0
        fi
    done
    rm -f "$out"
    log "note: no PVH-bootable vmlinux in $(cat "$KDIR/release"): booting the bzImage (about 3 s slower)"
    touch "$KDIR/vmlinux.none"
}

# boot_args: the -kernel and firmware arguments for qemu.
boot_args() {
    if [ "${VCAN_VM_FAST:-1}" != 0 ] && [ -f "$KDIR/vmlinux" ]; then
        BOOT_ARGS=(-kernel "$KDIR/vmlinux")
    else
        BOOT_ARGS=(-kernel "$KDIR/vmlinuz")
    fi
    # qboot: a minimal firmware that boots straight into the kernel (SeaBIOS costs ~0.4 s more).
    if [ "${VCAN_VM_FAST:-1}" != 0 ] && [ -f /usr/share/qemu/qboot.rom ]; then
        BOOT_ARGS+=(-bios /usr/share/qemu/qboot.rom)
    fi
}

# ---------------------------------------------------------------------------------------------
# Copying files into an initramfs tree, with the shared libraries of ELF programs.

is_elf() { [ "$(head -c 4 "$1" 2>/dev/null | tr -d '\0')" = $'\x7fELF' ]; }

declare -A IN_BASE=() # paths already in the cached base archive ("/lib/.../libc.so.6")

# shared_libs FILE: absolute paths of the libraries the dynamic loader maps for FILE.
shared_libs() {
    local out
    if ! out=$(LC_ALL=C ldd "$1" 2>&1); then
        case $out in
        *"not a dynamic executable"* | *"statically linked"*) return 0 ;;
        *) die "ldd $1 failed: $out" ;;
        esac
    fi
    if grep -q 'not found' <<<"$out"; then
        die "$1 needs libraries this host does not have: $(grep 'not found' <<<"$out" | tr -s ' \t' ' ')"
    fi
    awk '$2 == "=>" && $3 ~ /^\// { print $3 } $1 ~ /^\// { print $1 }' <<<"$out"
}

# put ROOT SRC [DEST]: copy SRC (dereferenced) to ROOT/DEST (default: SRC's own absolute path),
# then the shared libraries if SRC is an ELF file.
put() {
    local root=$1 src=$2 dest=${3:-$2} lib libs
    [ -e "$src" ] || die "no such file: $src"
    if [ -z "${IN_BASE[$dest]:-}" ]; then
        mkdir -p "$root$(dirname "$dest")"
        cp -L --preserve=mode "$src" "$root$dest"
    fi
    if is_elf "$src"; then
        libs=$(shared_libs "$src") # (a failure inside exits here, under set -e)
        for lib in $libs; do
            [ -n "${IN_BASE[$lib]:-}" ] && continue
            [ -e "$root$lib" ] && continue
            mkdir -p "$root$(dirname "$lib")"
            cp -L --preserve=mode "$lib" "$root$lib"
        done
    fi
}

# put_any ROOT PATH: a file (with its libraries) or a whole directory, at its absolute path.
put_any() {
    local root=$1 p
    p=$(realpath -s -- "$2")
    if [ -d "$p" ]; then
        mkdir -p "$root$p"
        cp -a -L "$p/." "$root$p/"
    elif [ -e "$p" ]; then
        put "$root" "$p"
    else
        die "--include $2: no such file or directory"
    fi
}

make_cpio() { # make_cpio ROOT OUT
    (cd "$1" && find . -mindepth 1 | LC_ALL=C sort | cpio -o -H newc -R 0:0 --quiet) >"$2.part"
    mv "$2.part" "$2"
}

# ensure_base: sets BASE to the cached archive holding busybox, modules, can-utils and /init.
ensure_base() {
    local key rel
    rel=$(cat "$KDIR/release")
    key=$(
        {
            cat "$SCRIPT_PATH" "$HELPERS/init" "$KDIR/package"
            sha256sum /bin/busybox
            for t in "${CAN_UTILS[@]}" ip; do
                if command -v "$t" >/dev/null 2>&1; then
                    sha256sum "$(command -v "$t")"
                fi
            done
            dpkg-query -W -f '${Package} ${Version}\n' libc6 2>/dev/null || true
        } | sha256sum | cut -c1-16
    )
    BASE=$CACHE/base-$key.cpio
    if [ ! -f "$BASE" ] || [ ! -f "$BASE.list" ]; then
        local t0 tmp root a t ko
        t0=$(now_ms)
        tmp=$(mktemp -d "$CACHE/tmp.base.XXXXXX")
        TMP_DIRS+=("$tmp")
        root=$tmp/root
        mkdir -p "$root"/{bin,sbin,usr/bin,usr/sbin,lib,lib64,etc,proc,sys,dev,tmp,run,root,var/tmp,vcan-vm}
        put "$root" /bin/busybox
        # Every applet as a symlink to busybox, where nothing else sits.
        while IFS= read -r a; do
            [ -e "$root/$a" ] || [ -L "$root/$a" ] || ln -s /bin/busybox "$root/$a"
        done < <(/bin/busybox --list-full)
        for t in "${CAN_UTILS[@]}"; do
            if command -v "$t" >/dev/null 2>&1; then
                put "$root" "$(command -v "$t")" "/usr/bin/$t"
            fi
        done
        # iproute2's ip, when the host has it, as /usr/sbin/ip: it knows -details, vxcan peers and
        # CAN link options (busybox ip only adds a vcan). PATH has /usr/sbin first, so programs
        # that search PATH get it; busybox sh runs its own applet for a bare `ip`.
        if command -v ip >/dev/null 2>&1; then
            put "$root" "$(readlink -f "$(command -v ip)")" /usr/sbin/ip
        fi
        if [ ! -x "$root/usr/bin/candump" ] || [ ! -x "$root/usr/bin/cansend" ]; then
            die "candump/cansend not found (can-utils)"
        fi
        mkdir -p "$root/lib/modules/$rel"
        : >"$root/vcan-vm/modules"
        while IFS= read -r ko; do
            cp "$KDIR/modules/$ko" "$root/lib/modules/$rel/$ko"
            echo "/lib/modules/$rel/$ko" >>"$root/vcan-vm/modules"
        done <"$KDIR/modules.order"
        cp "$HELPERS/init" "$root/init"
        chmod 755 "$root/init"
        echo 'root:x:0:0:root:/root:/bin/sh' >"$root/etc/passwd"
        printf 'root:x:0:\ntty:x:5:\n' >"$root/etc/group"
        echo vcan-vm >"$root/etc/hostname"
        printf '127.0.0.1 localhost vcan-vm\n::1 localhost\n' >"$root/etc/hosts"
        # A console node, so that even the kernel's first messages to init have somewhere to go.
        mknod -m 600 "$root/dev/console" c 5 1 2>/dev/null || true
        make_cpio "$root" "$BASE"
        (cd "$root" && find . -mindepth 1 ! -type d | sed 's/^\.//' | LC_ALL=C sort) >"$BASE.list"
        rm -rf "$tmp"
        # Older bases are for other kernels or script versions.
        find "$CACHE" -maxdepth 1 -name 'base-*.cpio*' ! -name "base-$key.cpio*" -delete
        log "initramfs base built in $(secs_since "$t0") s ($(du -k "$BASE" | cut -f1) KiB, $BASE)"
    fi
    local p
    while IFS= read -r p; do IN_BASE[$p]=1; done <"$BASE.list"
}

# prepare: install, kernel, base; under a lock so that concurrent runs share one download.
prepare_vm() {
    mkdir -p "$CACHE"
    exec 9>"$CACHE/.lock"
    flock 9
    ensure_tools vm
    ensure_kernel
    ensure_vmlinux
    ensure_base
    flock -u 9
}

# ---------------------------------------------------------------------------------------------
# Host mode: this kernel's own vcan, when it has it.

host_has_vcan() {
    local ifc
    command -v ip >/dev/null 2>&1 || return 1
    if [ "$(id -u)" = 0 ] && command -v modprobe >/dev/null 2>&1; then
        modprobe -q vcan 2>/dev/null || true
        modprobe -q can-raw 2>/dev/null || true
    fi
    for ifc in ${IFACES//,/ }; do
        if ! ip -d link show dev "$ifc" 2>/dev/null | grep -qw vcan; then
            [ "$(id -u)" = 0 ] || return 1
            ip link add dev "$ifc" type vcan 2>/dev/null || return 1
        fi
        if ! ip link show dev "$ifc" 2>/dev/null | grep -qE '[<,]UP[,>]'; then
            [ "$(id -u)" = 0 ] || return 1
            ip link set up "$ifc" 2>/dev/null || return 1
        fi
    done
}

# run_on_host: the jobs run in turn, here; exits with the verdict.
run_on_host() {
    ensure_tools host
    log "running on the host: its kernel has vcan (${IFACES//,/ })"
    local i rc first=0 t0 timed_out e dir name
    dir=$(mktemp -d)
    TMP_DIRS+=("$dir")
    for ((i = 0; i < ${#JOB_NAMES[@]}; i++)); do
        name=${JOB_NAMES[$i]}
        printf '%s' "${JOB_SCRIPTS[$i]}" >"$dir/$i.sh"
        echo "@@VCAN-BEGIN name=$name"
        t0=$(now_ms)
        set +e
        (
            cd "${CWD_OPT:-$PWD}" || exit "$EXIT_BENCH"
            for e in "${ENVS[@]}"; do export "${e?}"; done
            export VCAN_BENCH=host VCAN_IFACES="${IFACES//,/ }"
            exec timeout -k 5 "$TIMEOUT" sh "$dir/$i.sh"
        ) </dev/null
        rc=$?
        set -e
        timed_out=0
        [ "$rc" = 124 ] && timed_out=1
        echo
        echo "@@VCAN-RESULT name=$name exit=$rc seconds=$(secs_since "$t0") timeout=$timed_out"
        if [ "$timed_out" = 1 ]; then
            log "$name: ran out of time (${TIMEOUT} s)"
        fi
        log "$name: exit $rc in $(secs_since "$t0") s"
        if [ "$rc" != 0 ] && [ "$first" = 0 ]; then
            first=$rc
        fi
    done
    exit "$first"
}

# ---------------------------------------------------------------------------------------------
# VM mode

shq() { # shell-quote one word for sh
    printf "'%s'" "${1//\'/\'\\\'\'}"
}

# put_package_dir ROOT DIR: a package's folder without its target/ and .git/ (test fixtures).
put_package_dir() {
    mkdir -p "$1$2"
    tar -C "$2" --exclude=./target --exclude=./.git -cf - . | tar -C "$1$2" -xf -
}

# run_in_vm: builds the initramfs, boots it, reads the results; exits with the verdict.
run_in_vm() {
    local t0 tmp root i j p e t_start=$T_START t_prepared=$T_PREPARED
    tmp=$(mktemp -d "$CACHE/tmp.run.XXXXXX")
    TMP_DIRS+=("$tmp")
    root=$tmp/root
    mkdir -p "$root/vcan-vm/jobs"
    for p in "${PKG_DIRS[@]}"; do
        put_package_dir "$root" "$p"
    done
    for p in "${JOB_FILES[@]}" "${INCLUDES[@]}"; do
        [ -n "$p" ] && put_any "$root" "$p"
    done
    # Settings for /init.
    echo "${IFACES//,/ }" >"$root/vcan-vm/ifaces"
    echo "$TIMEOUT" >"$root/vcan-vm/timeout"
    echo "${CWD_OPT:-/}" >"$root/vcan-vm/cwd"
    : >"$root/vcan-vm/env"
    for e in "${ENVS[@]}"; do
        echo "export ${e%%=*}=$(shq "${e#*=}")" >>"$root/vcan-vm/env"
    done
    for ((i = 0; i < ${#JOB_NAMES[@]}; i++)); do
        j=$root/vcan-vm/jobs/$(printf '%03d' "$i")
        mkdir -p "$j"
        echo "${JOB_NAMES[$i]}" >"$j/name"
        printf '%s' "${JOB_SCRIPTS[$i]}" >"$j/cmd"
    done
    make_cpio "$root" "$tmp/run.cpio"
    cat "$BASE" "$tmp/run.cpio" >"$tmp/initrd"
    local t_initrd initrd_mb mem
    t_initrd=$(now_ms)
    initrd_mb=$(($(stat -c %s "$tmp/initrd") / 1048576 + 1))
    # The archive sits in memory twice while it unpacks, and the files stay in memory after.
    mem=$MEMORY
    [ "$mem" -lt $((512 + 3 * initrd_mb)) ] && mem=$((512 + 3 * initrd_mb))

    local limit=$((BOOT_TIMEOUT + ${#JOB_NAMES[@]} * (TIMEOUT + 10)))
    local log_file=$tmp/console.log
    # Carriage returns and the firmware's terminal escapes off the console.
    local CONSOLE_FILTER='s/\r$//; s/\x1b\[[0-9;?]*[A-Za-z]//g; s/\x1bc//g'
    boot_args
    local qemu=(qemu-system-x86_64 -accel tcg -m "$mem" -smp "$SMP" -nodefaults -nographic
        -serial stdio -no-reboot "${BOOT_ARGS[@]}" -initrd "$tmp/initrd"
        -append "console=ttyS0 quiet panic=-1 ${VCAN_VM_APPEND:-}")
    log "booting $(cat "$KDIR/release") under qemu TCG (${SMP} CPUs, ${mem} MB, initramfs ${initrd_mb} MB, limit ${limit} s)"
    t0=$(now_ms)
    local -a st
    set +e
    if [ "$QUIET" = 1 ]; then
        timeout -k 10 "$limit" "${qemu[@]}" </dev/null 2>&1 | sed -u "$CONSOLE_FILTER" | tee "$log_file" |
            sed -u -n '/^@@VCAN-BEGIN/,/^@@VCAN-RESULT/p'
    else
        timeout -k 10 "$limit" "${qemu[@]}" </dev/null 2>&1 | sed -u "$CONSOLE_FILTER" | tee "$log_file"
    fi
    st=("${PIPESTATUS[@]}")
    set -e
    local qemu_rc=${st[0]}
    local t_end
    t_end=$(now_ms)
    cp "$log_file" "$CACHE/last-console.log" 2>/dev/null || true

    # Judge the run from the console.
    local console="console: $CACHE/last-console.log"
    if [ "$qemu_rc" = 124 ] || [ "$qemu_rc" = 137 ]; then
        log "error: the VM ran out of time (${limit} s) ($console)"
        exit "$EXIT_TIMEOUT"
    fi
    local reason
    reason=$(sed -n 's/.*@@VCAN-SETUP-FAILED reason=//p' "$log_file" | head -n 1)
    [ -z "$reason" ] || die "the VM could not set up vcan: $reason ($console)"

    local first=0 line code tmo secs name
    for ((i = 0; i < ${#JOB_NAMES[@]}; i++)); do
        name=${JOB_NAMES[$i]}
        # The last such line: a job that printed a look-alike before it cannot fake its result.
        line=$(grep -aF "@@VCAN-RESULT name=$name " "$log_file" | tail -n 1 || true)
        if [ -z "$line" ]; then
            if grep -q 'Kernel panic' "$log_file"; then
                grep -m 1 -A 3 'Kernel panic' "$log_file" >&2 || true
                die "the VM's kernel panicked before '$name' ended ($console)"
            fi
            grep -q '@@VCAN-READY' "$log_file" ||
                die "the VM never reached vcan setup (qemu exit $qemu_rc; $console)"
            die "no result line for '$name': the VM stopped early (qemu exit $qemu_rc; $console)"
        fi
        code=$(sed -n 's/.* exit=\([0-9]*\).*/\1/p' <<<"$line")
        tmo=$(sed -n 's/.* timeout=\([01]\).*/\1/p' <<<"$line")
        secs=$(sed -n 's/.* seconds=\([0-9.]*\).*/\1/p' <<<"$line")
        [ -n "$code" ] || die "unreadable result line: $line"
        if [ "$tmo" = 1 ]; then
            log "$name: ran out of time (${TIMEOUT} s) in the VM"
            code=$EXIT_TIMEOUT
        fi
        log "$name: exit $code in ${secs} s"
        if [ "$code" != 0 ] && [ "$first" = 0 ]; then
            first=$code
        fi
    done
    local ready done_at
    ready=$(sed -n 's/.*@@VCAN-READY .*uptime=\([0-9.]*\).*/\1/p' "$log_file" | head -n 1)
    done_at=$(sed -n 's/.*@@VCAN-DONE uptime=\([0-9.]*\).*/\1/p' "$log_file" | head -n 1)
    log "times: prepare $(ms_as_s $((t_prepared - t_start))) s, initramfs $(ms_as_s $((t_initrd - t_prepared))) s," \
        "qemu $(ms_as_s $((t_end - t0))) s (guest uptime: vcan up at ${ready:-?} s, jobs done at ${done_at:-?} s)," \
        "total $(secs_since "$t_start") s"
    exit "$first"
}

# ---------------------------------------------------------------------------------------------
# Commands

T_START=$(now_ms)
T_PREPARED=$T_START
TMP_DIRS=()
cleanup() {
    local d
    for d in "${TMP_DIRS[@]}"; do rm -rf "$d"; done
}
trap cleanup EXIT

JOB_NAMES=()
JOB_SCRIPTS=() # each a small sh script: optional cd and exports, then exec of the command
JOB_FILES=()   # host programs the jobs run, copied into the VM with their libraries
JOB_ENV=()     # NAME=VALUE words for the next add_job only
PKG_DIRS=()    # package folders copied into the VM (cargo-test), without target/

job_name() { # a unique, safe name
    local n=${1##*/} i=2 m
    n=${n//[^A-Za-z0-9._-]/_}
    m=$n
    while printf '%s\n' "${JOB_NAMES[@]}" | grep -qxF -- "$m"; do
        m=$n-$i
        i=$((i + 1))
    done
    printf '%s' "$m"
}

# in_vm_image NAME: whether the VM image has the command NAME.
in_vm_image() {
    [ -n "${IN_BASE[/bin/$1]:-}${IN_BASE[/sbin/$1]:-}${IN_BASE[/usr/bin/$1]:-}${IN_BASE[/usr/sbin/$1]:-}" ]
}

# add_job CWD ARGV...: a job running ARGV in CWD (empty: the default). A program given as a path,
# or found on the host PATH but not in the VM image, is copied into the VM.
add_job() {
    local cwd=$1 prog=$2 w e script=""
    shift 2
    if [[ $prog == */* ]]; then
        [ -f "$prog" ] || usage_error "no such program: $prog"
        prog=$(realpath -s -- "$prog")
        JOB_FILES+=("$prog")
    elif [ "$MODE_CHOSEN" = vm ] && ! in_vm_image "$prog" &&
        command -v "$prog" >/dev/null 2>&1 && [ -f "$(command -v "$prog")" ]; then
        prog=$(command -v "$prog")
        log "copying $prog into the VM (not in its image)"
        JOB_FILES+=("$prog")
    fi
    if [ -n "$cwd" ]; then
        script+="cd $(shq "$cwd") || exit $EXIT_BENCH"$'\n'
    fi
    for e in "${JOB_ENV[@]}"; do
        script+="export ${e%%=*}=$(shq "${e#*=}")"$'\n'
    done
    script+="exec"
    for w in "$prog" "$@"; do
        script+=" $(shq "$w")"
    done
    JOB_NAMES+=("$(job_name "$prog")")
    JOB_SCRIPTS+=("$script"$'\n')
    JOB_ENV=()
}

pass_env() { # the host variables that follow the commands inside
    local n extra=()
    local names=("${PASS_ENV[@]}")
    read -r -a extra <<<"${VCAN_VM_PASS_ENV:-}"
    names+=("${extra[@]}")
    while IFS= read -r n; do names+=("$n"); done < <(compgen -e | grep '^PETREL_' || true)
    for n in "${names[@]}"; do
        [[ $n =~ ^[A-Za-z_][A-Za-z0-9_]*$ ]] || usage_error "VCAN_VM_PASS_ENV: '$n' is no variable name"
        if [ -n "${!n+x}" ]; then
            ENVS=("$n=${!n}" "${ENVS[@]}")
        fi
    done
}

choose_mode() {
    check_settings
    if [ "$MODE" != vm ] && host_has_vcan; then
        MODE_CHOSEN=host
    elif [ "$MODE" = host ]; then
        die "VCAN_VM_MODE=host (--host), but this host has no usable vcan (${IFACES//,/ })"
    else
        MODE_CHOSEN=vm
        log "this kernel has no usable vcan: running in a qemu VM"
        prepare_vm
        T_PREPARED=$(now_ms)
    fi
}

# execute: runs the jobs and exits with their verdict.
execute() {
    pass_env
    if [ "$MODE_CHOSEN" = host ]; then
        run_on_host
    else
        run_in_vm
    fi
}

# parse_vm_options ARGS...: consumes the VM runner's own options; sets REST to what follows.
parse_vm_options() {
    REST=()
    while [ $# -gt 0 ]; do
        case $1 in
        --timeout | --include | --env | --cwd | --ifaces | --smp | --memory | --vm | --host)
            parse_option "$@"
            shift "$SHIFT_BY"
            ;;
        *) break ;;
        esac
    done
    REST=("$@")
}

SUBCOMMAND=${1:-help}
[ $# -gt 0 ] && shift
MODE_CHOSEN=""
CWD_OPT=${VCAN_VM_CWD:-}
case $SUBCOMMAND in
help | -h | --help)
    usage
    ;;
setup)
    check_settings
    prepare_vm
    log "ready: kernel $(cat "$KDIR/release") ($(tr '\n' ' ' <"$KDIR/package")), base $BASE, in $(secs_since "$T_START") s"
    ;;
clean)
    rm -rf "$CACHE"
    log "removed $CACHE"
    ;;
run)
    parse_vm_options "$@"
    set -- "${REST[@]}"
    [ "${1:-}" = -- ] && shift
    [ $# -gt 0 ] || usage_error "run: no command (run [OPTIONS] -- CMD [ARGS...])"
    [[ $1 == -* ]] && usage_error "run: unknown option '$1' (put the command after --)"
    [[ $1 != */* ]] || [ -f "$1" ] || usage_error "run: no such program: $1"
    choose_mode
    add_job "" "$@"
    execute
    ;;
run-tests)
    parse_vm_options "$@"
    set -- "${REST[@]}"
    bins=()
    while [ $# -gt 0 ] && [ "$1" != -- ]; do
        bins+=("$1")
        shift
    done
    [ "${1:-}" = -- ] && shift
    [ "${#bins[@]}" -gt 0 ] || usage_error "run-tests: no binary (run-tests [OPTIONS] BINARY... [-- TEST_ARGS...])"
    for b in "${bins[@]}"; do
        { [ -f "$b" ] && [ -x "$b" ]; } || usage_error "run-tests: '$b' is not an executable file"
    done
    choose_mode
    for b in "${bins[@]}"; do
        [[ $b == */* ]] || b=./$b
        add_job "" "$b" "$@"
    done
    execute
    ;;
cargo-test)
    parse_vm_options "$@"
    set -- "${REST[@]}"
    cargo_args=()
    while [ $# -gt 0 ] && [ "$1" != -- ]; do
        cargo_args+=("$1")
        shift
    done
    [ "${1:-}" = -- ] && shift
    command -v cargo >/dev/null 2>&1 || die "cargo-test: no cargo on PATH"
    command -v python3 >/dev/null 2>&1 || die "cargo-test: needs python3 to read cargo's JSON"
    mkdir -p "$CACHE"
    artifacts=$(mktemp "$CACHE/tmp.cargo.XXXXXX")
    TMP_DIRS+=("$artifacts")
    TMP_DIRS+=("$artifacts.json")
    log "cargo test --no-run ${cargo_args[*]}"
    cargo test --no-run --message-format=json-render-diagnostics "${cargo_args[@]}" >"$artifacts.json" ||
        die "cargo test --no-run ${cargo_args[*]} failed"
    # One line per executable: "test<TAB>path<TAB>package folder" or "bin<TAB>path<TAB>-".
    python3 - "$artifacts.json" >"$artifacts" <<'EOF'
import json, os, sys
seen = set()
for line in open(sys.argv[1]):
    try:
        m = json.loads(line)
    except ValueError:
        continue
    exe = m.get("executable") if m.get("reason") == "compiler-artifact" else None
    if not exe or exe in seen:
        continue
    seen.add(exe)
    if m["profile"]["test"]:
        print("test\t%s\t%s" % (exe, os.path.dirname(m["manifest_path"])))
    else:
        print("bin\t%s\t-" % exe)
EOF
    tests=()
    dirs=()
    while IFS=$'\t' read -r kind exe dir; do
        if [ "$kind" = test ]; then
            tests+=("$exe")
            dirs+=("$dir")
        else
            INCLUDES+=("$exe") # for CARGO_BIN_EXE_* and std::process::Command
        fi
    done <"$artifacts"
    [ "${#tests[@]}" -gt 0 ] || die "cargo test --no-run ${cargo_args[*]} built no test executable"
    choose_mode
    for ((k = 0; k < ${#tests[@]}; k++)); do
        log "test executable: ${tests[$k]}"
        if [ "$MODE_CHOSEN" = vm ] && ! printf '%s\n' "${PKG_DIRS[@]}" | grep -qxF -- "${dirs[$k]}"; then
            PKG_DIRS+=("${dirs[$k]}")
        fi
        # As cargo test does: in the package's folder, with CARGO_MANIFEST_DIR set.
        JOB_ENV=("CARGO_MANIFEST_DIR=${dirs[$k]}")
        add_job "${dirs[$k]}" "${tests[$k]}" "$@"
    done
    execute
    ;;
runner)
    [ $# -gt 0 ] || usage_error "runner: no binary"
    [ -f "$1" ] || usage_error "runner: '$1' is not a file"
    # cargo runs the binary in the package's folder: the same path (empty) in the VM.
    CWD_OPT=${VCAN_VM_CWD:-$PWD}
    for n in CARGO_MANIFEST_DIR CARGO_PKG_NAME CARGO_PKG_VERSION CARGO_CRATE_NAME CARGO_TARGET_TMPDIR; do
        if [ -n "${!n+x}" ]; then
            ENVS+=("$n=${!n}")
        fi
    done
    choose_mode
    add_job "" "$@"
    execute
    ;;
*)
    usage_error "unknown command '$SUBCOMMAND'"
    ;;
esac
