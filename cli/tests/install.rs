//! Installing Petrel on a vehicle computer (docs/install.md): `cargo install` into a root of
//! one's choosing, the Debian package (built by scripts/deb.sh, installed into a Debian chroot)
//! and its systemd unit (`systemd-analyze verify`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Instant;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .canonicalize()
        .unwrap()
}

/// The target directory of this build: `TARGET/<profile>/deps/<test>`.
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.ancestors()
        .nth(3)
        .expect("TARGET/PROFILE/deps/TEST")
        .to_path_buf()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn cargo_install_puts_a_working_petrel_into_the_root_it_is_given() {
    // As docs/install.md says, with --debug and this build's target directory so that it
    // reuses what `cargo test` compiled (offline: nothing is downloaded).
    let root = tempfile::tempdir().unwrap();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let t = Instant::now();
    let o = Command::new(cargo)
        .args(["install", "--path"])
        .arg(repo().join("cli"))
        .arg("--root")
        .arg(root.path())
        .args(["--offline", "--locked", "--debug"])
        .env("CARGO_TARGET_DIR", target_dir())
        .output()
        .expect("cargo runs");
    assert!(o.status.success(), "{}", text(&o));
    eprintln!("cargo install: {:.1} s", t.elapsed().as_secs_f64());
    let installed = root.path().join("bin/petrel");
    let o = Command::new(&installed).arg("--version").output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        String::from_utf8_lossy(&o.stdout),
        format!("petrel {}\n", env!("CARGO_PKG_VERSION"))
    );
}

/// Whether this machine can build the package and install it into a chroot (root, dpkg-deb,
/// dpkg-shlibdeps, strip, debootstrap, systemd-analyze); otherwise says why the test is
/// skipped, or fails when PETREL_REQUIRE_PACKAGE is set (scripts/test.sh installs them).
fn can_package(test: &str) -> bool {
    let root = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Uid:"))
                .and_then(|r| r.split_whitespace().nth(1).map(|u| u == "0"))
        })
        .unwrap_or(false);
    let tools = [
        "dpkg-deb",
        "dpkg-shlibdeps",
        "strip",
        "debootstrap",
        "systemd-analyze",
    ];
    let missing: Vec<&str> = tools
        .iter()
        .copied()
        .filter(|t| {
            !["/usr/bin", "/usr/sbin", "/bin", "/sbin"]
                .iter()
                .any(|d| Path::new(d).join(t).exists())
        })
        .collect();
    if root && missing.is_empty() {
        return true;
    }
    let why = format!(
        "SKIPPED {test}: it needs root (for chroot) and {tools:?}; root: {root}, missing: {missing:?}"
    );
    assert!(
        std::env::var_os("PETREL_REQUIRE_PACKAGE").is_none(),
        "{why} (PETREL_REQUIRE_PACKAGE is set)"
    );
    eprintln!("{why}");
    false
}

fn run(cmd: &mut Command) -> String {
    let o = cmd.output().expect("the command runs");
    assert!(o.status.success(), "{cmd:?}:\n{}", text(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn the_debian_package_installs_into_a_debian_chroot_where_petrel_runs_and_its_unit_verifies() {
    if !can_package("the_debian_package_installs_into_a_debian_chroot") {
        return;
    }
    // Large files: in the target directory, not /tmp; removed, pass or fail.
    let scratch = tempfile::Builder::new()
        .prefix("deb-test-")
        .tempdir_in(target_dir())
        .unwrap();
    let deb_sh = repo().join("scripts/deb.sh");
    let t = Instant::now();
    let deb = run(Command::new(&deb_sh)
        .arg("build")
        .arg("--petrel")
        .arg(env!("CARGO_BIN_EXE_petrel"))
        .arg("--out")
        .arg(scratch.path().join("deb"))
        .arg("--fast"));
    let deb = PathBuf::from(deb.trim());
    eprintln!("package built in {:.1} s", t.elapsed().as_secs_f64());
    let contents = run(Command::new("dpkg-deb").arg("--contents").arg(&deb));
    for file in [
        "./usr/bin/petrel",
        "./lib/systemd/system/petrel-up@.service",
        "./usr/share/doc/petrel/install.md",
        "./usr/share/doc/petrel/copyright",
    ] {
        assert!(contents.contains(file), "{file} missing:\n{contents}");
    }
    let depends = run(Command::new("dpkg-deb")
        .args(["--field"])
        .arg(&deb)
        .arg("Depends"));
    assert!(depends.contains("libc6 (>= "), "{depends}");
    assert!(depends.contains("adduser"), "{depends}");

    // A minimal Debian with systemd, made once and kept in the target directory; the package
    // goes into a copy of it.
    let t = Instant::now();
    let pristine = target_dir().join("debian-chroot");
    run(Command::new(&deb_sh).arg("chroot").arg(&pristine));
    let root = scratch.path().join("root");
    run(Command::new("cp").arg("-a").arg(&pristine).arg(&root));
    eprintln!("chroot ready in {:.1} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    std::fs::copy(&deb, root.join("tmp/petrel.deb")).unwrap();
    let in_root = |args: &[&str]| run(Command::new("chroot").arg(&root).args(args));
    in_root(&["dpkg", "-i", "/tmp/petrel.deb"]);
    assert_eq!(
        in_root(&["petrel", "--version"]),
        format!("petrel {}\n", env!("CARGO_PKG_VERSION"))
    );
    // The postinst made the service's user and group.
    assert!(
        in_root(&["getent", "passwd", "petrel"]).contains(":/var/lib/petrel:"),
        "the user petrel"
    );
    in_root(&["getent", "group", "petrel"]);
    in_root(&["dpkg", "--status", "petrel"]);
    eprintln!("installed in {:.1} s", t.elapsed().as_secs_f64());

    // The unit as installed, for a vehicle in /srv/petrel/demo, verified against that system
    // (its executable, its users, systemd's own units): nothing to say.
    let instance = run(Command::new("systemd-escape").args(["--path", "/srv/petrel/demo"]));
    let unit = format!("petrel-up@{}.service", instance.trim());
    assert_eq!(unit, "petrel-up@srv-petrel-demo.service");
    let o = Command::new("systemd-analyze")
        .arg("verify")
        .arg(format!("--root={}", root.display()))
        .arg(&unit)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(text(&o), "", "systemd-analyze verify has something to say");
}
