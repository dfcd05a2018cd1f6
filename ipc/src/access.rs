//! Who may use a vehicle's files, and where they live.
//!
//! iceoryx2 keeps two kinds of files: shared memory in `/dev/shm` (a flat, world-writable
//! directory every user shares) and everything else (service descriptions, node details,
//! liveness monitors, the Unix sockets that wake listeners) under its *root path*, by default
//! `/tmp/iceoryx2`. Petrel gives every vehicle a **session** that puts them out of other
//! users' reach:
//!
//! - **A directory of its own.** The root path is `BASE/v<16 hex>/`, one per vehicle prefix,
//!   mode `0700` (`2770` with a group, see below), in a base directory that belongs to the
//!   user: `$PETREL_RUNTIME_DIR` if set; else `$XDG_RUNTIME_DIR/petrel` (a per-user tmpfs the
//!   login manager creates `0700`); else `/run/petrel` for root; else `/tmp/petrel-<uid>`
//!   (`0700`, and refused if someone else owns it). A directory that belongs to another user, is
//!   a symbolic link, or is writable by others is refused with an explanation. Without read
//!   access to it, another user can neither open a service nor wake a listener.
//! - **Unguessable shared-memory names.** Every file in `/dev/shm` is named after a session
//!   prefix `pt<12 hex>_` drawn from `/dev/urandom` when the session starts and kept in the
//!   vehicle's directory: another user cannot create one of the vehicle's files before the
//!   vehicle does (which would block it). iceoryx2 creates its shared memory owner-only
//!   (`0600`), except the 16-byte node counter (`…_node.<version>.global_mgmt`), which it makes
//!   `0666` on purpose (`enable_global_access`, not configurable, and `fchmod` ignores the
//!   umask). Right after creating a node, Petrel replaces that file with an owner-only copy
//!   (written to a new file, then renamed over it): a descriptor another user might have opened
//!   in the instant it was `0666` now points at a file nobody uses.
//! - **The last one out cleans up.** Every process of the vehicle holds a shared `flock` on
//!   `lock` in the vehicle's directory while it has the vehicle (any [`Vehicle`] handle that was
//!   used). The process whose handle goes last (it alone can take the lock exclusively) removes
//!   the session's shared memory (the node counter included), the vehicle's directory, and the
//!   base directory if it is empty. A session found with nobody holding the lock (every process
//!   killed) is stale: the next process to come removes what it left and starts a new one.
//! - **An optional group.** With a group ([`Vehicle::with_group`], `petrel play --group`, or
//!   `PETREL_GROUP`), the vehicle's directory is `2770` with that group, the base directory
//!   `0711`, and every process of the vehicle gives the group the access its owner has to the
//!   files it creates (`0660` shared memory and sockets, `0440` descriptions), right after
//!   creating them and every 10 ms after: operator accounts in the group can then `petrel
//!   send` and `petrel status` (with `PETREL_RUNTIME_DIR` pointing at the vehicle's base
//!   directory). Processes that join later find the group on the directory.
//!
//! What this does not protect against is said in `docs/security.md`: processes of the same user
//! (they can do anything the player can), root, and the exhaustion of `/dev/shm` itself.

use std::fmt;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::{DirBuilderExt, FileTypeExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use iceoryx2::config::Config;
use iceoryx2::prelude::{FileName, SemanticString};

use crate::naming::Vehicle;

/// Environment variable naming the base directory of the vehicles' files (it wins over every
/// default). Operator accounts of a vehicle with a group set it to the vehicle's base directory.
pub const RUNTIME_DIR_ENV: &str = "PETREL_RUNTIME_DIR";
/// Environment variable naming the group (name or number) of the vehicles a process sets up.
pub const GROUP_ENV: &str = "PETREL_GROUP";
/// Where POSIX shared memory lives on Linux.
pub const SHM_DIR: &str = "/dev/shm";

const LOCK_FILE: &str = "lock";
const SESSION_FILE: &str = "session";
const SESSION_HEX: usize = 12;
/// The longest path a Unix socket accepts (`sun_path` holds 108 bytes with the final NUL).
const MAX_SOCKET_PATH: usize = 107;
/// The longest decimal iceoryx2 id (a `u128`) in a socket's name.
const LONGEST_ID: usize = 39;
const SHARE_PERIOD: Duration = Duration::from_millis(10);
const OPEN_ATTEMPTS: usize = 20;

/// A vehicle's files could not be set up, or are not safe to use.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum AccessError {
    /// A file or directory could not be created, read or changed.
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The system's reason.
        error: String,
    },
    /// A directory Petrel would use belongs to someone else, is a symbolic link, or is open to
    /// other users.
    Untrusted {
        /// The directory.
        path: PathBuf,
        /// Why it is refused.
        reason: String,
    },
    /// No group of this name or number is known.
    UnknownGroup {
        /// The group as given.
        group: String,
    },
    /// This process is not a member of the group, so it cannot give files to it.
    NotInGroup {
        /// The group's name.
        group: String,
        /// Its number.
        gid: u32,
    },
    /// The vehicle's directory is too long for iceoryx2's Unix sockets.
    PathTooLong {
        /// The directory.
        path: PathBuf,
        /// The longest directory accepted.
        max: usize,
    },
    /// The session file of the vehicle's directory holds something else than a session prefix.
    BadSession {
        /// The file.
        path: PathBuf,
    },
}

impl fmt::Display for AccessError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AccessError::Io { path, what, error } => {
                let hint = if error.contains("ermission denied") {
                    format!("; is the vehicle another user's? Its processes must run as one user (or share a group, and set {RUNTIME_DIR_ENV} to its directory)")
                } else {
                    String::new()
                };
                write!(f, "cannot {what} `{}`: {error}{hint}", path.display())
            }
            AccessError::Untrusted { path, reason } => {
                write!(f, "refusing `{}`: {reason}", path.display())
            }
            AccessError::UnknownGroup { group } => {
                write!(f, "no group `{group}` in /etc/group; give its name or number")
            }
            AccessError::NotInGroup { group, gid } => write!(
                f,
                "this process is not in group `{group}` ({gid}): add the user to it (and log in again) before giving it the vehicle"
            ),
            AccessError::PathTooLong { path, max } => write!(
                f,
                "the vehicle's directory `{}` is longer than {max} bytes, too long for the Unix sockets iceoryx2 puts in it; set {RUNTIME_DIR_ENV} to a shorter directory",
                path.display()
            ),
            AccessError::BadSession { path } => write!(
                f,
                "`{}` does not hold a session prefix; stop every process of the vehicle and remove the directory",
                path.display()
            ),
        }
    }
}

impl std::error::Error for AccessError {}

fn io_error(path: &Path, what: &'static str, error: io::Error) -> AccessError {
    AccessError::Io {
        path: path.to_path_buf(),
        what,
        error: error.to_string(),
    }
}

/// A Unix group given the vehicle's files, for operator accounts.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Group {
    name: String,
    gid: u32,
}

impl Group {
    /// The group `name` (from `/etc/group`) or number.
    pub fn lookup(name: &str) -> Result<Group, AccessError> {
        let unknown = || AccessError::UnknownGroup {
            group: name.to_owned(),
        };
        let groups = fs::read_to_string("/etc/group").unwrap_or_default();
        let entries = groups.lines().filter_map(|line| {
            let mut fields = line.split(':');
            let n = fields.next()?;
            let gid = fields.nth(1)?.parse::<u32>().ok()?;
            Some((n, gid))
        });
        if let Ok(gid) = name.parse::<u32>() {
            let n = entries
                .clone()
                .find(|(_, g)| *g == gid)
                .map_or_else(|| gid.to_string(), |(n, _)| n.to_owned());
            return Ok(Group { name: n, gid });
        }
        if name.is_empty() {
            return Err(unknown());
        }
        entries
            .clone()
            .find(|(n, _)| *n == name)
            .map(|(n, gid)| Group {
                name: n.to_owned(),
                gid,
            })
            .ok_or_else(unknown)
    }

    /// The group's name (its number when `/etc/group` does not name it).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The group's number.
    pub fn gid(&self) -> u32 {
        self.gid
    }
}

impl fmt::Display for Group {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.name, self.gid)
    }
}

/// Who this process is: effective user and groups, read from `/proc/self/status` (no `unsafe`
/// call needed).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Identity {
    pub(crate) uid: u32,
    pub(crate) gid: u32,
    pub(crate) groups: Vec<u32>,
}

impl Identity {
    pub(crate) fn current() -> Result<Identity, AccessError> {
        let path = Path::new("/proc/self/status");
        let text = fs::read_to_string(path).map_err(|e| io_error(path, "read", e))?;
        let field = |key: &str| -> Vec<u32> {
            text.lines()
                .find_map(|l| l.strip_prefix(key))
                .map(|rest| {
                    rest.split_whitespace()
                        .filter_map(|n| n.parse().ok())
                        .collect()
                })
                .unwrap_or_default()
        };
        let (uids, gids) = (field("Uid:"), field("Gid:"));
        let (Some(&uid), Some(&gid)) = (uids.get(1), gids.get(1)) else {
            return Err(AccessError::Io {
                path: path.to_path_buf(),
                what: "read the effective user from",
                error: "no Uid:/Gid: lines".into(),
            });
        };
        Ok(Identity {
            uid,
            gid,
            groups: field("Groups:"),
        })
    }

    fn in_group(&self, gid: u32) -> bool {
        self.uid == 0 || self.gid == gid || self.groups.contains(&gid)
    }
}

/// FNV-1a, 64 bits: a stable name for a vehicle's directory, the same in every process whatever
/// Rust built it.
fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn random_hex(n: usize) -> Result<String, AccessError> {
    let path = Path::new("/dev/urandom");
    let mut bytes = vec![0u8; n.div_ceil(2)];
    File::open(path)
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(|e| io_error(path, "read", e))?;
    let mut hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    hex.truncate(n);
    Ok(hex)
}

fn is_session_prefix(text: &str) -> bool {
    text.len() == SESSION_HEX + 3
        && text.starts_with("pt")
        && text.ends_with('_')
        && text[2..2 + SESSION_HEX]
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// The base directory and whether it was given (`PETREL_RUNTIME_DIR`: created if absent, never
/// changed or removed by Petrel) or chosen.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Base {
    path: PathBuf,
    given: bool,
}

fn base_dir(id: &Identity, shared: bool) -> Result<Base, AccessError> {
    if let Some(dir) = std::env::var_os(RUNTIME_DIR_ENV).filter(|d| !d.is_empty()) {
        let path = PathBuf::from(dir);
        if !path.is_absolute() {
            return Err(AccessError::Untrusted {
                path,
                reason: format!("{RUNTIME_DIR_ENV} must be an absolute path"),
            });
        }
        return Ok(Base { path, given: true });
    }
    // A per-user runtime directory is the right home, unless operators of other accounts must
    // reach the vehicle (it is 0700 and not ours to open).
    if !shared {
        if let Some(xdg) = std::env::var_os("XDG_RUNTIME_DIR").map(PathBuf::from) {
            let ours = fs::symlink_metadata(&xdg)
                .is_ok_and(|m| m.is_dir() && m.uid() == id.uid && m.mode() & 0o077 == 0);
            if xdg.is_absolute() && ours {
                return Ok(Base {
                    path: xdg.join("petrel"),
                    given: false,
                });
            }
        }
    }
    if id.uid == 0 && fs::symlink_metadata("/run").is_ok_and(|m| m.is_dir()) {
        return Ok(Base {
            path: PathBuf::from("/run/petrel"),
            given: false,
        });
    }
    Ok(Base {
        path: PathBuf::from(format!("/tmp/petrel-{}", id.uid)),
        given: false,
    })
}

fn mode_of(m: &fs::Metadata) -> u32 {
    m.mode() & 0o7777
}

fn chmod(path: &Path, mode: u32) -> Result<(), AccessError> {
    fs::set_permissions(path, fs::Permissions::from_mode(mode))
        .map_err(|e| io_error(path, "change the mode of", e))
}

/// Creates (if absent) and checks the base directory.
fn prepare_base(base: &Base, id: &Identity, shared: bool) -> Result<(), AccessError> {
    let path = &base.path;
    let want = if shared { 0o711 } else { 0o700 };
    // Whoever creates it, the mode is settled below from what it is then: a process that
    // created it must not undo what another one (with a group) did meanwhile.
    match fs::DirBuilder::new()
        .recursive(base.given)
        .mode(want)
        .create(path)
    {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io_error(path, "create the directory", e)),
    }
    let m = fs::symlink_metadata(path).map_err(|e| io_error(path, "inspect", e))?;
    if !m.is_dir() {
        return Err(AccessError::Untrusted {
            path: path.clone(),
            reason: "it is not a directory (a symbolic link?); remove it".into(),
        });
    }
    let mode = mode_of(&m);
    if mode & 0o002 != 0 {
        return Err(AccessError::Untrusted {
            path: path.clone(),
            reason: format!(
                "every user may write in it (mode {mode:o}); give {RUNTIME_DIR_ENV} a directory only you (or an administrator) can write in"
            ),
        });
    }
    if m.uid() == id.uid {
        if !base.given {
            // Ours: nobody else reads it; keep the traversal another group vehicle needs (the
            // umask may also have taken it).
            let keep_x = if mode & 0o011 == 0o011 || shared {
                0o011
            } else {
                0
            };
            let fixed = 0o700 | keep_x;
            if mode != fixed {
                chmod(path, fixed)?;
            }
        }
        return Ok(());
    }
    if base.given && (m.uid() == 0 || mode & 0o020 == 0) {
        // A directory an administrator (or the vehicle's user, for an operator) provides.
        return Ok(());
    }
    Err(AccessError::Untrusted {
        path: path.clone(),
        reason: format!(
            "it belongs to user {}, not to you: someone may have created it to read or block the vehicle's files; remove it (as root), or set {RUNTIME_DIR_ENV} to a directory of yours",
            m.uid()
        ),
    })
}

/// Creates (if absent) and checks the vehicle's directory; returns the group its files are
/// shared with, if any, and whether this process owns the directory.
fn prepare_vehicle_dir(
    dir: &Path,
    id: &Identity,
    group: Option<&Group>,
) -> Result<(Option<u32>, bool), AccessError> {
    let want = if group.is_some() { 0o2770 } else { 0o700 };
    // As for the base: the mode is settled from what it is once it exists, whoever made it.
    match fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io_error(dir, "create the directory", e)),
    }
    let m = fs::symlink_metadata(dir).map_err(|e| io_error(dir, "inspect", e))?;
    if !m.is_dir() {
        return Err(AccessError::Untrusted {
            path: dir.to_path_buf(),
            reason: "it is not a directory (a symbolic link?); remove it".into(),
        });
    }
    let mode = mode_of(&m);
    if m.uid() == id.uid {
        if let Some(g) = group {
            if m.gid() != g.gid {
                std::os::unix::fs::chown(dir, None, Some(g.gid))
                    .map_err(|e| io_error(dir, "give the group", e))?;
            }
            if mode != want {
                chmod(dir, want)?;
            }
            return Ok((Some(g.gid), true));
        }
        // Without a group of our own, a directory shared before (by the process that set the
        // vehicle up) stays shared; anything open to every user is closed.
        let shared = mode & 0o070 == 0o070;
        let fixed = if shared { 0o2770 } else { 0o700 };
        if mode != fixed {
            chmod(dir, fixed)?;
        }
        return Ok((shared.then_some(m.gid()), true));
    }
    // Another user's directory: usable only as a member of the group it is shared with.
    if mode & 0o007 == 0 && mode & 0o070 == 0o070 && id.in_group(m.gid()) {
        if let Some(g) = group {
            if g.gid != m.gid() {
                return Err(AccessError::Untrusted {
                    path: dir.to_path_buf(),
                    reason: format!(
                        "it is the vehicle of user {}, shared with group {}, not {g}",
                        m.uid(),
                        m.gid()
                    ),
                });
            }
        }
        return Ok((Some(m.gid()), false));
    }
    Err(AccessError::Untrusted {
        path: dir.to_path_buf(),
        reason: format!(
            "it is the vehicle of user {} (mode {mode:o}), not shared with a group of yours: run as that user, or join the group its player gives it (`petrel play --group`)",
            m.uid()
        ),
    })
}

/// Opens the lock file without following a link and without blocking on a FIFO someone put
/// there; read-write when possible (creating it), read-only otherwise (a `flock` needs no more).
fn open_lock(dir: &Path, uid: u32, group: Option<u32>) -> Result<File, AccessError> {
    let path = dir.join(LOCK_FILE);
    let flags = libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_CLOEXEC;
    let mode = if group.is_some() { 0o660 } else { 0o600 };
    let file = match OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .mode(mode)
        .custom_flags(flags)
        .open(&path)
    {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::PermissionDenied => OpenOptions::new()
            .read(true)
            .custom_flags(flags)
            .open(&path)
            .map_err(|e| io_error(&path, "open", e))?,
        Err(e) => return Err(io_error(&path, "open", e)),
    };
    let m = file.metadata().map_err(|e| io_error(&path, "inspect", e))?;
    if !m.is_file() {
        return Err(AccessError::Untrusted {
            path,
            reason: "it is not a regular file".into(),
        });
    }
    if let Some(gid) = group {
        give_to_group(&file, &m, uid, gid, mode).map_err(|e| io_error(&path, "share", e))?;
    }
    Ok(file)
}

/// Gives an open file of ours to the group, with `mode` (the umask, or a process of the vehicle
/// that came before the group was given, may have left it the owner's alone).
fn give_to_group(file: &File, m: &fs::Metadata, uid: u32, gid: u32, mode: u32) -> io::Result<()> {
    if m.uid() != uid {
        return Ok(());
    }
    if m.gid() != gid {
        std::os::unix::fs::fchown(file, None, Some(gid))?;
    }
    if mode_of(m) != mode {
        file.set_permissions(fs::Permissions::from_mode(mode))?;
    }
    Ok(())
}

/// Gives the session file to the group (see [`give_to_group`]).
fn share_session(dir: &Path, uid: u32, gid: u32) -> Result<(), AccessError> {
    let path = dir.join(SESSION_FILE);
    let file = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(&path)
        .map_err(|e| io_error(&path, "open", e))?;
    let m = file.metadata().map_err(|e| io_error(&path, "inspect", e))?;
    if m.is_file() {
        give_to_group(&file, &m, uid, gid, 0o640).map_err(|e| io_error(&path, "share", e))?;
    }
    Ok(())
}

fn read_session(dir: &Path) -> Result<Option<String>, AccessError> {
    let path = dir.join(SESSION_FILE);
    let mut text = String::new();
    match OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(&path)
    {
        Ok(f) => {
            // A session file is 16 bytes: never read more than that, whatever is there.
            f.take(64)
                .read_to_string(&mut text)
                .map_err(|e| io_error(&path, "read", e))?;
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io_error(&path, "read", e)),
    }
    let prefix = text.trim();
    if is_session_prefix(prefix) {
        Ok(Some(prefix.to_owned()))
    } else {
        Err(AccessError::BadSession { path })
    }
}

/// Writes a new session prefix, whole or not at all: into a file of its own, then linked to
/// `session` (which fails if another process published one first: its prefix wins).
fn publish_session(dir: &Path, group: Option<u32>) -> Result<String, AccessError> {
    let prefix = format!("pt{}_", random_hex(SESSION_HEX)?);
    let temp = dir.join(format!("session.{}.{}", std::process::id(), &prefix[2..10]));
    let mode = if group.is_some() { 0o640 } else { 0o600 };
    let written = OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&temp)
        .and_then(|mut f| {
            f.write_all(format!("{prefix}\n").as_bytes())?;
            if group.is_some() {
                f.set_permissions(fs::Permissions::from_mode(mode))?;
            }
            f.sync_all()
        });
    if let Err(e) = written {
        let _ = fs::remove_file(&temp);
        return Err(io_error(&temp, "write", e));
    }
    let target = dir.join(SESSION_FILE);
    let linked = fs::hard_link(&temp, &target);
    let _ = fs::remove_file(&temp);
    match linked {
        Ok(()) => Ok(prefix),
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
            read_session(dir)?.ok_or(AccessError::BadSession { path: target })
        }
        Err(e) => Err(io_error(&target, "create", e)),
    }
}

/// Removes this user's shared-memory files named after `prefix` (a session prefix, checked: an
/// empty or malformed prefix would name other vehicles' files).
fn remove_shm(prefix: &str, uid: u32) -> usize {
    if !is_session_prefix(prefix) {
        return 0;
    }
    let Ok(entries) = fs::read_dir(SHM_DIR) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        if !entry.file_name().to_string_lossy().starts_with(prefix) {
            continue;
        }
        let path = entry.path();
        // Only our own regular files: a name someone else chose to look like ours is theirs.
        let ours = fs::symlink_metadata(&path).is_ok_and(|m| m.is_file() && m.uid() == uid);
        if ours && fs::remove_file(&path).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// Removes what iceoryx2 keeps in the vehicle's directory (every entry but `keep`).
fn clear_dir(dir: &Path, keep: &[&str]) -> usize {
    let Ok(entries) = fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        if keep.iter().any(|k| name.to_str() == Some(*k)) {
            continue;
        }
        let path = entry.path();
        // std's remove_dir_all never follows a symbolic link out of the tree.
        let gone = match entry.file_type() {
            Ok(t) if t.is_dir() => fs::remove_dir_all(&path),
            _ => fs::remove_file(&path),
        };
        if gone.is_ok() {
            removed += 1;
        }
    }
    removed
}

/// What the sharing with a group needs, apart from the session (the thread must not keep the
/// session, and its lock, alive).
#[derive(Debug, Clone)]
struct Sharing {
    dir: PathBuf,
    shm_prefix: String,
    uid: u32,
    gid: u32,
}

impl Sharing {
    /// Gives the group the access the owner has, on every file of the session this process
    /// owns. Errors are left for the next round: a file may be going as it is looked at.
    fn share(&self) {
        if let Ok(entries) = fs::read_dir(SHM_DIR) {
            for entry in entries.flatten() {
                if entry
                    .file_name()
                    .to_string_lossy()
                    .starts_with(&self.shm_prefix)
                {
                    // /dev/shm is sticky: nobody else can swap our file for a link between the
                    // look and the change, so the path is safe here.
                    let path = entry.path();
                    if let Ok(m) = fs::symlink_metadata(&path) {
                        self.share_one(&path, &m, Kind::Shm);
                    }
                }
            }
        }
        self.share_tree(&self.dir.clone(), 0);
    }

    fn share_tree(&self, dir: &Path, depth: usize) {
        let Ok(entries) = fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            // The vehicle's directory is writable by the group: a member could swap an entry
            // for a link to a file of ours elsewhere. Open the entry itself (O_PATH, no
            // following) and change it through its descriptor's /proc path.
            let Ok(handle) = OpenOptions::new()
                .read(true)
                .custom_flags(libc::O_PATH | libc::O_NOFOLLOW | libc::O_CLOEXEC)
                .open(&path)
            else {
                continue;
            };
            let Ok(m) = handle.metadata() else { continue };
            let by_fd = PathBuf::from(format!("/proc/self/fd/{}", handle.as_raw_fd()));
            if m.is_dir() {
                self.share_one(&by_fd, &m, Kind::Dir);
                if depth < 3 {
                    // Through the descriptor too: the directory listed is the one looked at,
                    // even if a link took its name since.
                    self.share_tree(&by_fd, depth + 1);
                }
            } else if m.file_type().is_socket() {
                self.share_one(&by_fd, &m, Kind::Socket);
            } else if m.is_file() {
                self.share_one(&by_fd, &m, Kind::Description);
            }
        }
    }

    fn share_one(&self, path: &Path, m: &fs::Metadata, kind: Kind) {
        if m.uid() != self.uid || (kind == Kind::Shm && !m.is_file()) {
            return;
        }
        let mode = mode_of(m);
        if kind == Kind::Shm && mode & 0o007 != 0 {
            // The node counter as iceoryx2 leaves it: the process that created it replaces it
            // (`Session::secure`); changing its mode here would hide it from that.
            return;
        }
        let owner = (mode >> 6) & 0o7;
        let want = match kind {
            // Shared memory is ready once its owner may read it (iceoryx2 creates it
            // write-only while it initialises it); sockets are ready at once.
            Kind::Shm | Kind::Socket if owner & 0o4 != 0 => (mode & 0o7700) | ((owner & 0o6) << 3),
            Kind::Dir => (mode & 0o7700) | 0o2000 | (owner << 3),
            // Descriptions are final once read-only (iceoryx2 tells a description still being
            // written by its owner's write bit: it must not change); liveness monitors and
            // the lock stay as they are.
            Kind::Description if owner == 0o4 => (mode & 0o7700) | 0o040,
            _ => return,
        };
        if m.gid() != self.gid {
            let _ = std::os::unix::fs::chown(path, None, Some(self.gid));
        }
        if mode != want {
            let _ = fs::set_permissions(path, fs::Permissions::from_mode(want));
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Shm,
    Dir,
    Socket,
    Description,
}

/// The thread that shares new files with the group every [`SHARE_PERIOD`].
#[derive(Debug)]
struct Sharer {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Sharer {
    fn start(sharing: Sharing) -> Option<Sharer> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("petrel-share".into())
            .spawn(move || {
                while !flag.load(Ordering::Relaxed) {
                    sharing.share();
                    std::thread::sleep(SHARE_PERIOD);
                }
            })
            .ok()?;
        Some(Sharer {
            stop,
            thread: Some(thread),
        })
    }
}

impl Drop for Sharer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A process's membership in a vehicle: its directory, its session prefix, the iceoryx2
/// configuration that puts every file there, and the shared lock that says the process is in.
#[derive(Debug)]
pub(crate) struct Session {
    base: Base,
    dir: PathBuf,
    shm_prefix: String,
    config: Config,
    uid: u32,
    group: Option<u32>,
    owns_dir: bool,
    /// Stopped before the lock goes.
    sharer: std::sync::Mutex<Option<Sharer>>,
    lock: File,
}

impl Session {
    /// Joins (or starts) the session of `vehicle`, in the directory its prefix names.
    pub(crate) fn open(vehicle: &Vehicle) -> Result<Session, AccessError> {
        let id = Identity::current()?;
        let group = match vehicle.group() {
            Some(g) => Some(g.clone()),
            None => match std::env::var(GROUP_ENV) {
                Ok(g) if !g.is_empty() => Some(Group::lookup(&g)?),
                _ => None,
            },
        };
        if let Some(g) = &group {
            if !id.in_group(g.gid) {
                return Err(AccessError::NotInGroup {
                    group: g.name.clone(),
                    gid: g.gid,
                });
            }
        }
        let base = base_dir(&id, group.is_some())?;
        let dir = base.path.join(format!("v{:016x}", fnv1a(vehicle.prefix())));
        let longest = MAX_SOCKET_PATH - (SESSION_HEX + 3) - LONGEST_ID - ".event".len() - 1;
        if dir.as_os_str().len() > longest {
            return Err(AccessError::PathTooLong {
                path: dir,
                max: longest,
            });
        }
        for _ in 0..OPEN_ATTEMPTS {
            match Self::try_open(vehicle, &id, &base, &dir, group.as_ref()) {
                Ok(Some(session)) => return Ok(session),
                // The lock went with its directory (a last process cleaning up) as we came.
                Ok(None) => {}
                // So did a directory, between its creation and its use: again.
                Err(AccessError::Io { .. }) if !dir.is_dir() => {}
                Err(e) => return Err(e),
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        Err(AccessError::Io {
            path: dir,
            what: "settle the session in",
            error: "other processes kept creating and removing it".into(),
        })
    }

    fn try_open(
        vehicle: &Vehicle,
        id: &Identity,
        base: &Base,
        dir: &Path,
        group: Option<&Group>,
    ) -> Result<Option<Session>, AccessError> {
        prepare_base(base, id, group.is_some())?;
        let (shared_with, owns_dir) = prepare_vehicle_dir(dir, id, group)?;
        let lock = open_lock(dir, id.uid, shared_with)?;
        let lock_path = dir.join(LOCK_FILE);
        match lock.try_lock() {
            Ok(()) => {
                // Nobody else holds the vehicle: whatever a former session left (every process
                // killed) is stale.
                if let Ok(Some(old)) = read_session(dir) {
                    remove_shm(&old, id.uid);
                }
                if owns_dir {
                    clear_dir(dir, &[LOCK_FILE]);
                }
                lock.lock_shared()
                    .map_err(|e| io_error(&lock_path, "lock", e))?;
            }
            Err(fs::TryLockError::WouldBlock) => lock
                .lock_shared()
                .map_err(|e| io_error(&lock_path, "lock", e))?,
            Err(fs::TryLockError::Error(e)) => return Err(io_error(&lock_path, "lock", e)),
        }
        // The lock is ours only if it is still the directory's (a last process may have removed
        // the directory while we waited).
        let held = lock
            .metadata()
            .map_err(|e| io_error(&lock_path, "inspect", e))?;
        match fs::symlink_metadata(&lock_path) {
            Ok(now) if now.ino() == held.ino() && now.dev() == held.dev() => {}
            _ => return Ok(None),
        }
        let shm_prefix = match read_session(dir)? {
            Some(p) => p,
            None => publish_session(dir, shared_with)?,
        };
        if let Some(gid) = shared_with {
            share_session(dir, id.uid, gid)?;
        }
        let mut config = vehicle.config().clone();
        let mut root = dir.as_os_str().as_encoded_bytes().to_vec();
        root.push(b'/');
        let root = iceoryx2::prelude::Path::new(&root).map_err(|_| AccessError::PathTooLong {
            path: dir.to_path_buf(),
            max: 255,
        })?;
        config.global.set_root_path(&root);
        config.global.prefix =
            FileName::new(shm_prefix.as_bytes()).map_err(|_| AccessError::BadSession {
                path: dir.join(SESSION_FILE),
            })?;
        let session = Session {
            base: base.clone(),
            dir: dir.to_path_buf(),
            shm_prefix,
            config,
            uid: id.uid,
            group: shared_with,
            owns_dir,
            sharer: std::sync::Mutex::new(None),
            lock,
        };
        Ok(Some(session))
    }

    /// The iceoryx2 configuration of every node of the vehicle.
    pub(crate) fn config(&self) -> &Config {
        &self.config
    }

    /// The vehicle's directory (iceoryx2's root path).
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// The prefix of the session's files in `/dev/shm`.
    pub(crate) fn shm_prefix(&self) -> &str {
        &self.shm_prefix
    }

    /// The group the vehicle's files are shared with.
    pub(crate) fn group(&self) -> Option<u32> {
        self.group
    }

    /// After a node was created: replaces the node counter iceoryx2 left open to every user
    /// with a copy only the vehicle can use, and shares new files with the group.
    pub(crate) fn secure(&self) -> Result<(), AccessError> {
        let suffix = self.config.global.node.global_mgmt_suffix.to_string();
        let entries = fs::read_dir(SHM_DIR).map_err(|e| io_error(Path::new(SHM_DIR), "list", e))?;
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if !(name.starts_with(&self.shm_prefix) && name.ends_with(&suffix)) {
                continue;
            }
            let path = entry.path();
            let Ok(m) = fs::symlink_metadata(&path) else {
                continue;
            };
            // Only iceoryx2's finished counter (0666) is replaced: one still being initialised
            // (write-only) is left to the process creating it, which secures it in turn.
            if m.is_file() && m.uid() == self.uid && mode_of(&m) & 0o006 != 0 {
                self.replace_private(&path)?;
            }
        }
        self.share_now();
        Ok(())
    }

    fn replace_private(&self, path: &Path) -> Result<(), AccessError> {
        let content = fs::read(path).map_err(|e| io_error(path, "read", e))?;
        if content.len() > 4096 {
            // iceoryx2's counter is 16 bytes; anything else is not what we think it is.
            return Ok(());
        }
        let temp = PathBuf::from(SHM_DIR).join(format!(
            "{}tmp{}_{}",
            self.shm_prefix,
            std::process::id(),
            random_hex(8)?
        ));
        let mode = if self.group.is_some() { 0o660 } else { 0o600 };
        let written = OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&temp)
            .and_then(|mut f| {
                f.write_all(&content)?;
                if let Some(gid) = self.group {
                    std::os::unix::fs::fchown(&f, None, Some(gid))?;
                    f.set_permissions(fs::Permissions::from_mode(mode))?;
                }
                Ok(())
            })
            .and_then(|()| fs::rename(&temp, path));
        if let Err(e) = written {
            let _ = fs::remove_file(&temp);
            return Err(io_error(path, "make private", e));
        }
        Ok(())
    }

    /// Shares this process's new files with the group now (after creating a node or a port),
    /// and starts the thread that shares the ones created later.
    pub(crate) fn share_now(&self) {
        let Some(gid) = self.group else { return };
        let sharing = Sharing {
            dir: self.dir.clone(),
            shm_prefix: self.shm_prefix.clone(),
            uid: self.uid,
            gid,
        };
        sharing.share();
        let mut sharer = self.sharer.lock().unwrap_or_else(|p| p.into_inner());
        if sharer.is_none() {
            *sharer = Sharer::start(sharing);
        }
    }

    /// Removes what iceoryx2 left of the session (its shared memory and its part of the
    /// directory), keeping the session itself; the number of files removed.
    pub(crate) fn clear(&self) -> usize {
        remove_shm(&self.shm_prefix, self.uid) + clear_dir(&self.dir, &[LOCK_FILE, SESSION_FILE])
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        // The sharing thread first: it must not touch files being removed.
        drop(self.sharer.lock().unwrap_or_else(|p| p.into_inner()).take());
        // The last process of the vehicle (it alone can have the lock exclusively) removes
        // what is left. Files of another user of the group are theirs to remove: a directory
        // that is not ours is left to its owner, who removes it with the session's remains
        // when it next comes.
        if self.lock.try_lock().is_ok() {
            remove_shm(&self.shm_prefix, self.uid);
            if self.owns_dir {
                let _ = fs::remove_dir_all(&self.dir);
                if !self.base.given {
                    // Only when empty: other vehicles may live there.
                    let _ = fs::remove_dir(&self.base.path);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn session_prefixes_are_checked() {
        assert!(is_session_prefix("pt0123456789ab_"));
        assert!(!is_session_prefix("pt0123456789AB_"));
        assert!(!is_session_prefix(""));
        assert!(!is_session_prefix("pt_"));
        assert!(!is_session_prefix("petrel_auv_"));
    }

    #[test]
    fn the_identity_is_read() {
        let id = Identity::current().unwrap();
        let meta = fs::metadata("/proc/self").unwrap();
        assert_eq!(id.uid, meta.uid());
    }

    #[test]
    fn groups_are_found_by_name_or_number() {
        let root = Group::lookup("0").unwrap();
        assert_eq!(root.gid(), 0);
        assert_eq!(Group::lookup(root.name()).unwrap().gid(), 0);
        assert!(matches!(
            Group::lookup("no-such-group-at-all"),
            Err(AccessError::UnknownGroup { .. })
        ));
    }

    fn is_root() -> bool {
        Identity::current().unwrap().uid == 0
    }

    fn given(path: &Path) -> Base {
        Base {
            path: path.to_path_buf(),
            given: true,
        }
    }

    #[test]
    fn a_base_directory_that_is_a_link_or_open_to_all_is_refused() {
        let id = Identity::current().unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let real = tmp.path().join("real");
        fs::create_dir(&real).unwrap();
        let link = tmp.path().join("link");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        assert!(matches!(
            prepare_base(&given(&link), &id, false),
            Err(AccessError::Untrusted { .. })
        ));
        chmod(&real, 0o777).unwrap();
        let e = prepare_base(&given(&real), &id, false).unwrap_err();
        assert!(e.to_string().contains("every user may write"), "{e}");
        chmod(&real, 0o700).unwrap();
        prepare_base(&given(&real), &id, false).unwrap();
    }

    #[test]
    fn directories_another_user_created_are_refused() {
        if !is_root() {
            eprintln!("SKIPPED: giving a directory to another user needs root");
            return;
        }
        let id = Identity::current().unwrap();
        let tmp = tempfile::tempdir().unwrap();
        // What another user could do where the base would be /tmp/petrel-<uid>: create it
        // first, to read or block the vehicle's files.
        let squat = tmp.path().join("petrel-1000");
        fs::create_dir(&squat).unwrap();
        chmod(&squat, 0o755).unwrap();
        std::os::unix::fs::chown(&squat, Some(65_534), Some(65_534)).unwrap();
        let chosen = Base {
            path: squat.clone(),
            given: false,
        };
        let e = prepare_base(&chosen, &id, false).unwrap_err();
        assert!(e.to_string().contains("belongs to user 65534"), "{e}");
        // The same for a vehicle's directory: not shared with a group of ours, refused.
        let dir = tmp.path().join("vehicle");
        fs::create_dir(&dir).unwrap();
        chmod(&dir, 0o700).unwrap();
        std::os::unix::fs::chown(&dir, Some(65_534), Some(65_534)).unwrap();
        let other = Identity {
            uid: 1_000,
            gid: 1_000,
            groups: vec![],
        };
        let e = prepare_vehicle_dir(&dir, &other, None).unwrap_err();
        assert!(e.to_string().contains("vehicle of user 65534"), "{e}");
        // Shared with a group the process is in: an operator's way in.
        chmod(&dir, 0o2770).unwrap();
        let operator = Identity {
            uid: 1_000,
            gid: 1_000,
            groups: vec![65_534],
        };
        assert_eq!(
            prepare_vehicle_dir(&dir, &operator, None).unwrap(),
            (Some(65_534), false)
        );
    }

    #[test]
    fn directory_names_are_stable() {
        // The name every process of a vehicle computes must not depend on the build.
        assert_eq!(fnv1a(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a("a"), 0xaf63_dc4c_8601_ec8c);
    }
}
