//! The sink of [`crate::io::atomic::write_atomic`]: a buffer that goes to the file whole, past the page
//! cache (`O_DIRECT`) where the system allows it.
//!
//! # Why past the page cache
//! With every format at 0.8 M hexes a run writes 0.9 GB. Through the page cache the kernel
//! copies every byte into pages it has just taken from its free list; on the shared virtual
//! machines these figures come from, that copy was the largest single cost of the run (38 % of
//! the CPU samples, about 0.5 GB/s: the host backs freshly used guest pages on first touch). A
//! direct write hands the device the buffer's own pages, the same few from the first buffer to
//! the last, and the thread waits for the device instead of copying: the other thread and the
//! formatting of the next blocks have the CPU meanwhile. The file is synced before it is renamed,
//! as before, so the data reach the disk at the same point either way.
//!
//! Direct writes want the buffer's address, their length and the file offset aligned to the
//! device's block: the buffer is aligned to [`ALIGN`] and written in multiples of it; the tail,
//! shorter than a block, is written through the page cache. Where the file system refuses
//! direct I/O (tmpfs, some network file systems: `EINVAL` when the flag is set or at the first
//! write) or the platform has none, every write goes through the page cache, as it always did.
//! The bytes of the file are the same.

use std::fs::File;
use std::io::{self, Write};

/// Alignment of the buffer and of every direct write: the largest logical block of common
/// devices (4 KiB sectors; 512-byte ones divide it).
const ALIGN: usize = 4096;

/// Bytes of the buffer, a multiple of [`ALIGN`]: one write per mebibyte, as the `BufWriter` it
/// replaces.
const BUFFER: usize = 1 << 20;

/// A buffered writer to `file` that writes whole buffers, directly where it can, and fails once
/// the run is interrupted (a signal stops a long write within one buffer). [`Sink::finish`]
/// writes what is left; dropping the sink without it loses that.
pub struct Sink<'f> {
    file: &'f File,
    /// `BUFFER + ALIGN` bytes: the buffer proper is the aligned window at `start`.
    bytes: Vec<u8>,
    start: usize,
    len: usize,
    direct: bool,
}

impl<'f> Sink<'f> {
    pub fn new(file: &'f File) -> Self {
        let bytes = vec![0u8; BUFFER + ALIGN];
        let start = bytes.as_ptr().align_offset(ALIGN);
        let direct = set_direct(file, true).is_ok();
        Sink { file, bytes, start, len: 0, direct }
    }

    /// Writes the `n` first bytes of the buffer (a multiple of [`ALIGN`] while direct).
    fn write_out(&mut self, n: usize) -> io::Result<()> {
        crate::io::output::check_interrupted()?;
        let mut at = 0;
        while at < n {
            let data = &self.bytes[self.start + at..self.start + n];
            match (&*self.file).write(data) {
                Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
                Ok(k) => at += k,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                // Refused at the first write (or after a partial one): the page cache from here.
                Err(e) if self.direct && e.raw_os_error() == Some(EINVAL) => {
                    set_direct(self.file, false)?;
                    self.direct = false;
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Writes what the buffer holds: its whole blocks as any buffer, the tail through the page
    /// cache.
    pub fn finish(mut self) -> io::Result<()> {
        let whole = self.len / ALIGN * ALIGN;
        self.write_out(whole)?;
        if self.direct {
            set_direct(self.file, false)?;
            self.direct = false;
        }
        self.bytes.copy_within(self.start + whole..self.start + self.len, self.start);
        self.write_out(self.len - whole)
    }
}

impl Write for Sink<'_> {
    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        let n = data.len().min(BUFFER - self.len);
        let at = self.start + self.len;
        self.bytes[at..at + n].copy_from_slice(&data[..n]);
        self.len += n;
        if self.len == BUFFER {
            self.write_out(BUFFER)?;
            self.len = 0;
        }
        Ok(n)
    }
    /// Nothing: the buffer goes out whole, and the rest at [`Sink::finish`].
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(target_os = "linux")]
const EINVAL: i32 = rustix::io::Errno::INVAL.raw_os_error();
#[cfg(not(target_os = "linux"))]
const EINVAL: i32 = -1;

/// Sets or clears `O_DIRECT` on `file`.
#[cfg(target_os = "linux")]
fn set_direct(file: &File, on: bool) -> io::Result<()> {
    use rustix::fs::{fcntl_getfl, fcntl_setfl, OFlags};
    let flags = fcntl_getfl(file)?;
    fcntl_setfl(file, if on { flags | OFlags::DIRECT } else { flags - OFlags::DIRECT })?;
    Ok(())
}

#[cfg(not(target_os = "linux"))]
fn set_direct(_: &File, on: bool) -> io::Result<()> {
    if on {
        Err(io::ErrorKind::Unsupported.into())
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The file holds what was written, for lengths about the block and the buffer, written in
    /// pieces of every size: whole, one byte, a block, a buffer and more.
    #[test]
    fn the_file_holds_every_byte_written() {
        let lengths = [0, 1, ALIGN - 1, ALIGN, ALIGN + 1, BUFFER - 1, BUFFER, BUFFER + 1, 3 * BUFFER + 4097];
        for len in lengths {
            let data: Vec<u8> = (0..len).map(|i| (i * 7 + i / 4096) as u8).collect();
            for piece in [len.max(1), 1, 1000, ALIGN, BUFFER + 3] {
                let tmp = tempfile::NamedTempFile::new().unwrap();
                let mut sink = Sink::new(tmp.as_file());
                for chunk in data.chunks(piece) {
                    sink.write_all(chunk).unwrap();
                }
                sink.finish().unwrap();
                assert!(std::fs::read(tmp.path()).unwrap() == data, "{len} bytes in pieces of {piece}");
            }
        }
    }

    /// A direct write refused (here: from a buffer off the alignment, which ext4 refuses with
    /// EINVAL) goes through the page cache instead, from where it stopped.
    #[test]
    fn a_refused_direct_write_goes_through_the_page_cache() {
        let data: Vec<u8> = (0..3 * BUFFER + 100).map(|i| (i % 251) as u8).collect();
        let tmp = tempfile::NamedTempFile::new().unwrap();
        let mut sink = Sink::new(tmp.as_file());
        sink.start += 1;
        sink.write_all(&data).unwrap();
        sink.finish().unwrap();
        assert!(std::fs::read(tmp.path()).unwrap() == data);
    }
}
