//! A window of a file mapped `MAP_SHARED`, for appending records without a system call each.
//!
//! The player's flight recorder writes each round of records before it sleeps, so that an
//! event is on record before it is acknowledged. Through `pwrite` that is a system call per
//! round (and, on ext4, a journal handle for the file's times). A store into a shared mapping
//! of the file lands in the page cache itself: once the copy is done the bytes are the
//! operating system's, and they survive a crash of the process exactly as written ones do
//! (not a power loss: that is what `fdatasync` is for, and the recorder's `sync` policy keeps
//! to it).
//!
//! A [`MappedWindow`] first **reserves** its part of the file with `fallocate` (which extends
//! the file and allocates its blocks), so that a full disk is an error returned here, never a
//! `SIGBUS` at a store into a page the file system cannot back; then maps it. The file's bytes
//! past what was written are zeros until written: whoever stops writing cuts them off (the
//! journal's writer does, when it rotates a segment and when it is dropped), and a reader
//! takes a run of zeros at the end of a file as its end.
//!
//! The contract a caller keeps: the file is not shrunk below the window's end while the window
//! lives (a store past the end of a file raises `SIGBUS`); drop the window first.

use std::fs::File;
use std::io;
use std::os::fd::AsRawFd;
use std::ptr::NonNull;

/// The size of a memory page (the alignment of a mapping's file offset).
pub fn page_size() -> u64 {
    // SAFETY: sysconf reads a constant of the system; no memory is involved.
    let n = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    if n > 0 {
        n as u64
    } else {
        4096
    }
}

/// Whether `e`, from [`MappedWindow::reserve`], says the file system cannot reserve space at
/// all (no `fallocate`), rather than that it has no room now.
pub fn cannot_reserve(e: &io::Error) -> bool {
    matches!(
        e.raw_os_error(),
        Some(libc::EOPNOTSUPP | libc::ENOSYS | libc::ENODEV)
    )
}

/// A reserved and mapped range `[start, end)` of a file, written by copying into memory.
#[derive(Debug)]
pub struct MappedWindow {
    ptr: NonNull<u8>,
    start: u64,
    len: usize,
}

impl MappedWindow {
    /// Reserves `[start, start + len)` of `file` (`fallocate`: the file grows to cover it, its
    /// blocks allocated) and maps it shared, writable. `start` is rounded down to a page. Fails
    /// when the file system has no room (`ENOSPC`) or cannot reserve (`EOPNOTSUPP`: the caller
    /// writes through the file instead), or cannot map. `file` must be open for reading and
    /// writing.
    pub fn reserve(file: &File, start: u64, len: usize) -> io::Result<MappedWindow> {
        let page = page_size();
        let aligned = start - start % page;
        let len = len
            .checked_add((start - aligned) as usize)
            .filter(|&l| l > 0 && l <= isize::MAX as usize)
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "window length"))?;
        let offset = libc::off_t::try_from(aligned)
            .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "window offset"))?;
        let length = libc::off_t::try_from(len)
            .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "window length"))?;
        // SAFETY: fallocate on an open descriptor with mode 0 (allocate and extend); no memory
        // of this process is involved.
        let r = unsafe { libc::fallocate(file.as_raw_fd(), 0, offset, length) };
        if r != 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: a fresh shared mapping of `len` bytes of an open file, at a page-aligned
        // offset, of a range the file now covers (reserved above); the kernel chooses the
        // address. The descriptor may be closed afterwards: the mapping stays.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                offset,
            )
        };
        if ptr == libc::MAP_FAILED {
            return Err(io::Error::last_os_error());
        }
        let ptr =
            NonNull::new(ptr.cast::<u8>()).ok_or_else(|| io::Error::other("mmap returned null"))?;
        Ok(MappedWindow {
            ptr,
            start: aligned,
            len,
        })
    }

    /// The file offset of the window's first byte.
    pub fn start(&self) -> u64 {
        self.start
    }

    /// The file offset just past the window.
    pub fn end(&self) -> u64 {
        self.start + self.len as u64
    }

    /// Whether `[offset, offset + len)` lies inside the window.
    pub fn covers(&self, offset: u64, len: usize) -> bool {
        offset >= self.start
            && offset
                .checked_add(len as u64)
                .is_some_and(|end| end <= self.end())
    }

    /// Copies `bytes` to the file at `offset`: when this returns, they are in the page cache,
    /// as after a `pwrite`. Fails (nothing copied) when the range is not inside the window.
    pub fn write_at(&mut self, offset: u64, bytes: &[u8]) -> io::Result<()> {
        if !self.covers(offset, bytes.len()) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "{} bytes at {offset} are outside the mapped window [{}, {})",
                    bytes.len(),
                    self.start,
                    self.end()
                ),
            ));
        }
        let at = (offset - self.start) as usize;
        // SAFETY: `[at, at + bytes.len())` lies inside the mapping (checked above), which lives
        // as long as `self`; `bytes` is ordinary memory of this process, so the two do not
        // overlap; `&mut self` makes this the only writer through the window.
        unsafe {
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), self.ptr.as_ptr().add(at), bytes.len());
        }
        Ok(())
    }
}

impl Drop for MappedWindow {
    fn drop(&mut self) {
        // SAFETY: the mapping was made in `reserve` with this address and length and is not
        // used after this point (the window is being dropped).
        unsafe {
            libc::munmap(self.ptr.as_ptr().cast(), self.len);
        }
    }
}

// SAFETY: the window is a plain memory range owned by this value; writes go through `&mut
// self`, so moving it to another thread is sound.
unsafe impl Send for MappedWindow {}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn bytes_copied_into_the_window_are_in_the_file_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        let file = std::fs::OpenOptions::new()
            .create_new(true)
            .read(true)
            .write(true)
            .open(&path)
            .unwrap();
        std::os::unix::fs::FileExt::write_at(&file, b"head", 0).unwrap();
        let mut w = MappedWindow::reserve(&file, 4, 10_000).unwrap();
        assert_eq!(w.start(), 0, "rounded down to the page");
        assert!(file.metadata().unwrap().len() >= 10_004, "reserved");
        w.write_at(4, b"record").unwrap();
        assert!(w.write_at(w.end() - 2, b"abc").is_err(), "past the window");
        // Read through another descriptor, before any unmap or sync: the page cache has it.
        let mut bytes = Vec::new();
        std::fs::File::open(&path)
            .unwrap()
            .read_to_end(&mut bytes)
            .unwrap();
        assert_eq!(&bytes[..10], b"headrecord");
        assert!(bytes[10..].iter().all(|&b| b == 0));
    }
}
