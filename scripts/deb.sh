#!/usr/bin/env bash
# The Debian package of Petrel (docs/install.md), made with dpkg-deb from a staging tree:
#
#   scripts/deb.sh build [--petrel FILE] [--out DIR] [--fast]
#       builds target/deb/petrel_VERSION_ARCH.deb (or into DIR): `petrel` (a release build,
#       `cargo build --release --locked -p petrel-cli`, unless --petrel names a binary), the
#       systemd unit petrel-up@.service, the user `petrel` made at install (postinst), and the
#       docs. Depends are computed by dpkg-shlibdeps from the binary, plus adduser. --fast
#       compresses with gzip -1 instead of xz (the tests: seconds rather than most of a
#       minute for a debug binary). Prints the package's path.
#   scripts/deb.sh chroot DIR
#       makes DIR a minimal Debian of this machine's release (debootstrap, with systemd and
#       adduser) to install the package into, once: a DIR already made is kept (the tests keep
#       theirs in target/debian-chroot and work on a copy). Needs root and the Debian mirror.
#
# Needs dpkg-deb, dpkg-shlibdeps (dpkg-dev) and strip (binutils); debootstrap for `chroot`.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"

die() { echo "deb.sh: $*" >&2; exit 2; }

build() {
    local petrel="" out="$repo/target/deb" compress=(-Zxz)
    while [ $# -gt 0 ]; do
        case "$1" in
            --petrel) petrel="$2"; shift 2 ;;
            --out) out="$2"; shift 2 ;;
            --fast) compress=(-Zgzip -z1); shift ;;
            *) die "unknown argument $1" ;;
        esac
    done
    if [ -z "$petrel" ]; then
        (cd "$repo" && cargo build --release --locked -p petrel-cli >&2)
        petrel="$repo/target/release/petrel"
    fi
    [ -x "$petrel" ] || die "$petrel is not an executable"
    local version arch
    version="$("$petrel" --version | awk '{print $2}')"
    arch="$(dpkg --print-architecture)"
    mkdir -p "$out"
    local work
    work="$(mktemp -d "$out/stage.XXXXXX")"
    trap 'rm -rf "$work"' RETURN
    local root="$work/root"

    install -d "$root/DEBIAN" "$root/usr/bin" "$root/lib/systemd/system" \
        "$root/usr/share/doc/petrel" "$root/etc/petrel/up"
    # Stripped: the package carries the program, not its debug information.
    strip --strip-unneeded -o "$root/usr/bin/petrel" "$petrel"
    chmod 0755 "$root/usr/bin/petrel"
    install -m 0644 "$repo/packaging/petrel-up@.service" "$root/lib/systemd/system/"
    install -m 0644 "$repo/docs/install.md" "$root/usr/share/doc/petrel/install.md"
    install -m 0644 "$repo/packaging/debian/copyright" "$root/usr/share/doc/petrel/copyright"
    install -m 0755 "$repo/packaging/debian/postinst" "$repo/packaging/debian/postrm" "$root/DEBIAN/"

    # The shared libraries' packages, as dpkg-shlibdeps reads them from the binary (it wants
    # a debian/control beside it).
    mkdir -p "$work/debian"
    printf 'Source: petrel\n\nPackage: petrel\nArchitecture: any\n' >"$work/debian/control"
    local shlibs
    shlibs="$(cd "$work" && dpkg-shlibdeps -O root/usr/bin/petrel 2>/dev/null | sed -n 's/^shlibs:Depends=//p')"
    [ -n "$shlibs" ] || die "dpkg-shlibdeps found no dependency for $petrel"

    cat >"$root/DEBIAN/control" <<EOF
Package: petrel
Version: $version
Architecture: $arch
Maintainer: Petrel developers <petrel@localhost>
Installed-Size: $(du -sk --exclude=DEBIAN "$root" | cut -f1)
Depends: $shlibs, adduser
Recommends: systemd
Suggests: graphviz
Section: misc
Priority: optional
Description: mission supervisor for autonomous vehicles, written as safe Petri nets
 Petrel supervises an autonomous vehicle's mission: Petri nets played by a player,
 software programs and a CAN data server over iceoryx2 shared memory. The package
 carries the petrel command and petrel-up@.service, which brings a vehicle up at
 boot from its project directory (see /usr/share/doc/petrel/install.md).
EOF
    (cd "$root" && find . -type f ! -path './DEBIAN/*' -printf '%P\0' | sort -z |
        xargs -0 md5sum >DEBIAN/md5sums)
    local deb="$out/petrel_${version}_${arch}.deb"
    dpkg-deb --root-owner-group "${compress[@]}" --build "$root" "$deb" >/dev/null
    echo "$deb"
}

# Unmounts whatever is mounted under $1 (the deepest first).
unmount_under() {
    findmnt -n -l -o TARGET | awk -v p="$1/" 'index($0, p) == 1' | sort -r |
        xargs -r -d '\n' umount -l || true
}

chroot_dir() {
    [ $# -eq 1 ] || die "usage: scripts/deb.sh chroot DIR"
    local dir="$1"
    if [ -f "$dir/.petrel-chroot" ]; then
        return 0
    fi
    [ "$(id -u)" -eq 0 ] || die "debootstrap needs root"
    local suite
    suite="$(. /etc/os-release && echo "$VERSION_CODENAME")"
    # What an interrupted debootstrap left: its mounts first, then the tree (never across a
    # mount into the host's /proc or /sys).
    if [ -d "$dir.partial" ]; then
        unmount_under "$dir.partial"
        rm -rf --one-file-system "$dir.partial"
    fi
    debootstrap --variant=minbase --include=adduser,systemd "$suite" "$dir.partial" \
        http://deb.debian.org/debian >"$dir.log" 2>&1 || {
        tail -n 20 "$dir.log" >&2
        unmount_under "$dir.partial"
        rm -rf --one-file-system "$dir.partial"
        die "debootstrap failed (its log: $dir.log)"
    }
    touch "$dir.partial/.petrel-chroot"
    rm -rf "$dir"
    mv "$dir.partial" "$dir"
    rm -f "$dir.log"
}

case "${1:-}" in
    build) shift; build "$@" ;;
    chroot) shift; chroot_dir "$@" ;;
    *) die "usage: scripts/deb.sh build [--petrel FILE] [--out DIR] | chroot DIR" ;;
esac
