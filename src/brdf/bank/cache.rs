//! Path banks on disk (issue 24): a bank is traced once per machine, not once per process.
//!
//! # The entry
//! One file per bank, named by [`entry_name`]: the alpha (for people) and a 64-bit digest of
//! everything the bank depends on (the format, the crate version, a digest of the sources
//! that trace it, every [`BankSpec`] field, the thinning cap, [`MAX_ORDER`], [`N_THETA`]).
//! A bank made by other code or for another spec is therefore not found, and the header
//! repeats all of it, so that an entry found under the right name is still checked field by
//! field before it is trusted.
//!
//! Layout, little-endian: the magic `PPRBANK\n`, the format ([`FORMAT`], `u32`), the code
//! version (`u32` length, UTF-8), `MAX_ORDER`, `N_THETA` (`u32`), the cap (`u64`), the spec
//! (`alpha` `f64`, `grid` `u64`, `correlation_length` `f64`, `rays` `u64`, `surfaces` `u32`,
//! `seed` `u64`, the autocorrelation's index in [`Autocorrelation::ALL`] `u32`), `lost`
//! (`u64`); per incidence node its rays (`u64`), albedos (`MAX_ORDER` `f64`), truncated
//! fraction (`f64`), weights (`MAX_ORDER - 1` `f64`) and the lengths of its path arrays and of
//! its backscatter arrays (`MAX_ORDER - 1` `u64` each, in `f32` values); then the path arrays
//! (`f32`), node by node, order by order, then the backscatter arrays likewise; last a checksum
//! (`u64`, [`Checksum`]) of everything before it.
//!
//! # Trust
//! [`PathBank::read_from`] rejects, with the reason, a file whose magic, format, version,
//! spec, cap or constants differ, whose lengths do not add up to the file's size (checked
//! before anything is allocated, so a corrupt length cannot ask for absurd memory), that
//! ends early, or whose checksum differs; it never panics on a bad file. [`cached`] then
//! traces the bank again and replaces the entry.
//!
//! # Concurrency
//! [`PathBank::write_to`] writes a temporary file of its own in the same directory (the
//! process id and a counter in its name), syncs it and renames it onto the entry: a reader
//! sees the old entry or the new one, never a mix, and two processes building the same
//! entry at once each write a complete file (the last rename wins; both are valid).

use super::{BankSpec, PathBank, MAX_ORDER, N_THETA};
use crate::reference::microsurface::Autocorrelation;
use crate::Result;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

/// The first bytes of an entry.
const MAGIC: [u8; 8] = *b"PPRBANK\n";
/// The layout's version (module docs); bump it with any change of the layout.
pub const FORMAT: u32 = 3;
/// The longest version string a reader accepts.
const MAX_VERSION_LEN: u32 = 256;
/// Entry files end with this.
const SUFFIX: &str = ".ppbank";
/// Temporary files older than this are left over from a process that died while writing.
const STALE_TMP: Duration = Duration::from_secs(3600);

/// The sources whose code decides a bank's paths: an edit to any of them changes
/// [`code_version`], so a bank traced by other code is never read (the crate version alone
/// does not change between commits).
const SOURCES: [&str; 4] = [
    include_str!("../bank.rs"),
    include_str!("../../reference/microsurface.rs"),
    include_str!("../../reference/trace.rs"),
    include_str!("../../reference/rng.rs"),
];

/// The version of the code that traces banks: the crate version and a digest of
/// [`SOURCES`], e.g. `0.1.0+3f2a...`.
pub fn code_version() -> String {
    let mut sum = Checksum::new();
    for s in SOURCES {
        sum.update(s.as_bytes());
        sum.update(&[0xff]);
    }
    format!("{}+{:016x}", env!("CARGO_PKG_VERSION"), sum.finish())
}

/// A 64-bit checksum: FNV-1a's offset basis and xor-then-multiply over little-endian
/// 64-bit words (an xorshift after each multiply spreads the high bits down), the tail
/// zero-padded and the byte count mixed in last. Each step is a bijection of the state, so
/// any change to a single word always changes the sum.
#[derive(Debug, Clone)]
pub struct Checksum {
    h: u64,
    buf: [u8; 8],
    n: usize,
    len: u64,
}

impl Default for Checksum {
    fn default() -> Self {
        Self::new()
    }
}

impl Checksum {
    pub fn new() -> Self {
        Checksum {
            h: 0xcbf2_9ce4_8422_2325,
            buf: [0; 8],
            n: 0,
            len: 0,
        }
    }

    #[inline]
    fn word(&mut self, w: u64) {
        self.h = (self.h ^ w).wrapping_mul(0x0000_0100_0000_01b3);
        self.h ^= self.h >> 29;
    }

    pub fn update(&mut self, mut bytes: &[u8]) {
        self.len += bytes.len() as u64;
        if self.n > 0 {
            let k = (8 - self.n).min(bytes.len());
            self.buf[self.n..self.n + k].copy_from_slice(&bytes[..k]);
            self.n += k;
            bytes = &bytes[k..];
            if self.n < 8 {
                return;
            }
            self.word(u64::from_le_bytes(self.buf));
            self.n = 0;
        }
        let mut words = bytes.chunks_exact(8);
        for w in &mut words {
            self.word(u64::from_le_bytes(w.try_into().unwrap()));
        }
        let rest = words.remainder();
        self.buf[..rest.len()].copy_from_slice(rest);
        self.n = rest.len();
    }

    pub fn finish(&self) -> u64 {
        let mut s = self.clone();
        if s.n > 0 {
            s.buf[s.n..].fill(0);
            s.word(u64::from_le_bytes(s.buf));
        }
        s.word(s.len);
        s.h
    }
}

/// Everything an entry depends on, as bytes (the spec's floats by their bits).
fn key_bytes(spec: &BankSpec, cap: usize, version: &str) -> Vec<u8> {
    let mut k = Vec::new();
    k.extend_from_slice(&MAGIC);
    k.extend_from_slice(&FORMAT.to_le_bytes());
    k.extend_from_slice(version.as_bytes());
    k.push(0);
    for x in [
        MAX_ORDER as u64,
        N_THETA as u64,
        cap as u64,
        spec.alpha.to_bits(),
        spec.grid as u64,
        spec.correlation_length.to_bits(),
        spec.rays,
        spec.surfaces as u64,
        spec.seed,
        spec.autocorrelation as u64,
    ] {
        k.extend_from_slice(&x.to_le_bytes());
    }
    k
}

/// The file name of `spec`'s bank thinned to `cap` (module docs).
pub fn entry_name(spec: &BankSpec, cap: usize) -> String {
    entry_name_for(spec, cap, &code_version())
}

pub(super) fn entry_name_for(spec: &BankSpec, cap: usize, version: &str) -> String {
    let mut sum = Checksum::new();
    sum.update(&key_bytes(spec, cap, version));
    // alpha is validated finite and in (0, 10]
    // the shape for people when it is not the default
    let shape = match spec.autocorrelation {
        Autocorrelation::Gaussian => String::new(),
        a => format!("-{}", a.name()),
    };
    format!(
        "bank-alpha{:.4}{shape}-{:016x}{SUFFIX}",
        spec.alpha,
        sum.finish()
    )
}

/// Why an entry was not read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Miss {
    /// No file (or it cannot be opened).
    Absent,
    /// A file that is not this bank, or is damaged: the reason.
    Invalid(String),
}

/// A writer that sums what passes through it.
struct Summed<W> {
    inner: W,
    sum: Checksum,
}

impl<W: Write> Write for Summed<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.sum.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Writes `bank` (thinned to `cap`) in the entry layout (module docs), checksum included.
fn encode<W: Write>(bank: &PathBank, cap: usize, version: &str, out: W) -> io::Result<W> {
    let bad = |what: &str| io::Error::new(io::ErrorKind::InvalidInput, what.to_string());
    if bank.paths.len() != N_THETA
        || bank.rays.len() != N_THETA
        || bank.albedo.len() != N_THETA
        || bank.truncated.len() != N_THETA
        || bank.weights.len() != N_THETA
        || bank.backscatter.len() != N_THETA
        || bank
            .paths
            .iter()
            .chain(&bank.backscatter)
            .any(|p| p.len() != MAX_ORDER - 1)
    {
        return Err(bad(
            "a path bank without N_THETA nodes of MAX_ORDER - 1 orders",
        ));
    }
    if version.len() > MAX_VERSION_LEN as usize {
        return Err(bad("version string too long"));
    }
    let mut w = Summed {
        inner: out,
        sum: Checksum::new(),
    };
    let s = &bank.spec;
    w.write_all(&MAGIC)?;
    w.write_all(&FORMAT.to_le_bytes())?;
    w.write_all(&(version.len() as u32).to_le_bytes())?;
    w.write_all(version.as_bytes())?;
    w.write_all(&(MAX_ORDER as u32).to_le_bytes())?;
    w.write_all(&(N_THETA as u32).to_le_bytes())?;
    w.write_all(&(cap as u64).to_le_bytes())?;
    w.write_all(&s.alpha.to_le_bytes())?;
    w.write_all(&(s.grid as u64).to_le_bytes())?;
    w.write_all(&s.correlation_length.to_le_bytes())?;
    w.write_all(&s.rays.to_le_bytes())?;
    w.write_all(&s.surfaces.to_le_bytes())?;
    w.write_all(&s.seed.to_le_bytes())?;
    w.write_all(&(s.autocorrelation as u32).to_le_bytes())?;
    w.write_all(&bank.lost.to_le_bytes())?;
    for i in 0..N_THETA {
        w.write_all(&bank.rays[i].to_le_bytes())?;
        for a in bank.albedo[i] {
            w.write_all(&a.to_le_bytes())?;
        }
        w.write_all(&bank.truncated[i].to_le_bytes())?;
        for x in bank.weights[i] {
            w.write_all(&x.to_le_bytes())?;
        }
        for p in bank.paths[i].iter().chain(&bank.backscatter[i]) {
            w.write_all(&(p.len() as u64).to_le_bytes())?;
        }
    }
    let mut bytes = Vec::new();
    for p in bank.paths.iter().chain(&bank.backscatter).flatten() {
        bytes.clear();
        bytes.extend(p.iter().flat_map(|x| x.to_le_bytes()));
        w.write_all(&bytes)?;
    }
    let sum = w.sum.finish();
    let mut out = w.inner;
    out.write_all(&sum.to_le_bytes())?;
    Ok(out)
}

/// The bytes of the header before the per-node records.
fn fixed_header_len(version_len: u64) -> u64 {
    8 + 4 + 4 + version_len + 4 + 4 + 8 + (8 + 8 + 8 + 8 + 4 + 8 + 4) + 8
}

/// The bytes of one node's record.
const NODE_RECORD: u64 = 8 + 8 * MAX_ORDER as u64 + 8 + 8 * (MAX_ORDER as u64 - 1) * 3;

/// A reader that sums what passes through it.
struct SummedReader<R> {
    inner: R,
    sum: Checksum,
}

impl<R: Read> SummedReader<R> {
    fn bytes<const N: usize>(&mut self) -> std::result::Result<[u8; N], String> {
        let mut b = [0u8; N];
        self.fill(&mut b)?;
        Ok(b)
    }
    fn fill(&mut self, b: &mut [u8]) -> std::result::Result<(), String> {
        self.inner.read_exact(b).map_err(|e| match e.kind() {
            io::ErrorKind::UnexpectedEof => "the file ends early".to_string(),
            _ => format!("read error: {e}"),
        })?;
        self.sum.update(b);
        Ok(())
    }
    fn u32(&mut self) -> std::result::Result<u32, String> {
        Ok(u32::from_le_bytes(self.bytes()?))
    }
    fn u64(&mut self) -> std::result::Result<u64, String> {
        Ok(u64::from_le_bytes(self.bytes()?))
    }
    fn f64(&mut self) -> std::result::Result<f64, String> {
        Ok(f64::from_le_bytes(self.bytes()?))
    }
}

fn expect<T: PartialEq + std::fmt::Debug>(
    what: &str,
    found: T,
    expected: T,
) -> std::result::Result<(), String> {
    if found == expected {
        Ok(())
    } else {
        Err(format!("{what} is {found:?}, expected {expected:?}"))
    }
}

/// The start of an entry's header: the magic, the format, and the code version's bytes.
fn read_version<R: Read>(r: &mut SummedReader<R>) -> std::result::Result<Vec<u8>, String> {
    let magic: [u8; 8] = r.bytes()?;
    if magic != MAGIC {
        return Err("not a path bank (magic bytes)".into());
    }
    expect("the format", r.u32()?, FORMAT)?;
    let vlen = r.u32()?;
    if vlen > MAX_VERSION_LEN {
        return Err(format!("a version string of {vlen} bytes"));
    }
    let mut v = vec![0u8; vlen as usize];
    r.fill(&mut v)?;
    Ok(v)
}

/// Reads a bank written by [`encode`] from `r`, a file of `file_len` bytes; it must be
/// `expected`'s bank thinned to `cap` by code of `version` (module docs).
fn decode<R: Read>(
    r: R,
    file_len: u64,
    expected: &BankSpec,
    cap: usize,
    version: &str,
) -> std::result::Result<PathBank, String> {
    let mut r = SummedReader {
        inner: r,
        sum: Checksum::new(),
    };
    if file_len < 8 {
        return Err(format!("{file_len} bytes: not a path bank"));
    }
    let v = read_version(&mut r)?;
    let found = String::from_utf8_lossy(&v);
    if found != version {
        return Err(format!(
            "written by pprender {found}, this is {version} (stale)"
        ));
    }
    expect("MAX_ORDER", r.u32()?, MAX_ORDER as u32)?;
    expect("N_THETA", r.u32()?, N_THETA as u32)?;
    expect("the thinning cap", r.u64()?, cap as u64)?;
    let spec = BankSpec {
        alpha: r.f64()?,
        grid: r.u64()? as usize,
        correlation_length: r.f64()?,
        rays: r.u64()?,
        surfaces: r.u32()?,
        seed: r.u64()?,
        autocorrelation: {
            let k = r.u32()?;
            *Autocorrelation::ALL
                .get(k as usize)
                .ok_or_else(|| format!("autocorrelation {k} unknown"))?
        },
    };
    let bits = |s: &BankSpec| {
        (
            s.alpha.to_bits(),
            s.grid,
            s.correlation_length.to_bits(),
            s.rays,
            s.surfaces,
            s.seed,
            s.autocorrelation,
        )
    };
    if bits(&spec) != bits(expected) {
        return Err(format!("a bank for {spec:?}, expected {expected:?}"));
    }
    let lost = r.u64()?;
    let mut rays = Vec::with_capacity(N_THETA);
    let mut albedo = Vec::with_capacity(N_THETA);
    let mut truncated = Vec::with_capacity(N_THETA);
    let mut weights = Vec::with_capacity(N_THETA);
    let mut lens = Vec::with_capacity(N_THETA);
    let header = fixed_header_len(v.len() as u64) + NODE_RECORD * N_THETA as u64;
    if file_len < header + 8 {
        return Err(format!(
            "{file_len} bytes, shorter than its header (the file ends early)"
        ));
    }
    let mut data_bytes = 0u64;
    for i in 0..N_THETA {
        rays.push(r.u64()?);
        let mut a = [0.0; MAX_ORDER];
        for x in &mut a {
            *x = r.f64()?;
        }
        albedo.push(a);
        truncated.push(r.f64()?);
        let mut w = [0.0; MAX_ORDER - 1];
        for x in &mut w {
            *x = r.f64()?;
        }
        weights.push(w);
        // the path arrays' lengths, then the backscatter arrays'
        let mut l = [0u64; 2 * (MAX_ORDER - 1)];
        for (k, x) in l.iter_mut().enumerate() {
            *x = r.u64()?;
            let n = (k % (MAX_ORDER - 1)) as u64 + 2;
            let per_path = if k < MAX_ORDER - 1 { 2 * n } else { 2 * n + 3 };
            if *x % per_path != 0 {
                return Err(format!("node {i} order {n}: {x} values, not whole paths"));
            }
            data_bytes = x
                .checked_mul(4)
                .and_then(|b| b.checked_add(data_bytes))
                .ok_or_else(|| format!("node {i}: absurd lengths"))?;
        }
        lens.push(l);
        let sane = a
            .iter()
            .chain([&truncated[i]])
            .all(|x| (0.0..=1.0).contains(x))
            && w.iter().all(|x| x.is_finite() && *x >= 1.0);
        if !sane {
            return Err(format!("node {i}: albedos or weights out of range"));
        }
    }
    // before anything is allocated: the lengths must add up to the file
    if header
        .checked_add(data_bytes)
        .and_then(|x| x.checked_add(8))
        != Some(file_len)
    {
        return Err(format!(
            "{file_len} bytes, but its lengths say {} (truncated or corrupt)",
            header as u128 + data_bytes as u128 + 8
        ));
    }
    let mut paths = Vec::with_capacity(N_THETA);
    let mut backscatter = Vec::with_capacity(N_THETA);
    let mut bytes = Vec::new();
    let halves = lens
        .iter()
        .map(|l| &l[..MAX_ORDER - 1])
        .chain(lens.iter().map(|l| &l[MAX_ORDER - 1..]));
    for (h, l) in halves.enumerate() {
        let mut node = Vec::with_capacity(MAX_ORDER - 1);
        for &len in l {
            bytes.resize(4 * len as usize, 0);
            r.fill(&mut bytes)?;
            node.push(
                bytes
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                    .collect::<Vec<f32>>(),
            );
        }
        if h < N_THETA {
            paths.push(node);
        } else {
            backscatter.push(node);
        }
    }
    let sum = r.sum.finish();
    let mut stored = [0u8; 8];
    r.inner
        .read_exact(&mut stored)
        .map_err(|_| "the file ends early".to_string())?;
    if u64::from_le_bytes(stored) != sum {
        return Err("checksum mismatch (corrupt)".into());
    }
    Ok(PathBank {
        spec,
        rays,
        paths,
        albedo,
        truncated,
        lost,
        weights,
        backscatter,
    })
}

/// Distinguishes the temporary files of one process.
static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

impl PathBank {
    /// Write the bank (thinned to `cap`, [`PathBank::thin`]) to `path`, atomically: a
    /// temporary file in the same directory, synced, then renamed onto `path` (module
    /// docs). The directory must exist.
    pub fn write_to(&self, path: &Path, cap: usize) -> io::Result<()> {
        self.write_versioned(path, cap, &code_version())
    }

    pub(super) fn write_versioned(&self, path: &Path, cap: usize, version: &str) -> io::Result<()> {
        let dir = path.parent().unwrap_or(Path::new("."));
        let name = path
            .file_name()
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "no file name"))?;
        let nanos = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let tmp = dir.join(format!(
            ".{}.tmp-{}-{}-{nanos}",
            name.to_string_lossy(),
            std::process::id(),
            TMP_COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let result = (|| {
            let file = OpenOptions::new().write(true).create_new(true).open(&tmp)?;
            let out = encode(self, cap, version, BufWriter::with_capacity(1 << 20, file))?;
            let file = out.into_inner().map_err(|e| e.into_error())?;
            file.sync_all()?;
            drop(file);
            fs::rename(&tmp, path)
        })();
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        } else {
            // the rename itself, durable (best effort: not every system opens directories)
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        result
    }

    /// Read the bank at `path`, which must be `expected`'s thinned to `cap` by this code
    /// (module docs); the reason when it is not.
    pub fn read_from(
        path: &Path,
        expected: &BankSpec,
        cap: usize,
    ) -> std::result::Result<PathBank, Miss> {
        Self::read_versioned(path, expected, cap, &code_version())
    }

    pub(super) fn read_versioned(
        path: &Path,
        expected: &BankSpec,
        cap: usize,
        version: &str,
    ) -> std::result::Result<PathBank, Miss> {
        let file = File::open(path).map_err(|_| Miss::Absent)?;
        let len = file
            .metadata()
            .map_err(|e| Miss::Invalid(format!("cannot stat: {e}")))?
            .len();
        decode(
            BufReader::with_capacity(1 << 20, file),
            len,
            expected,
            cap,
            version,
        )
        .map_err(Miss::Invalid)
    }
}

/// Warned once per process that the disk cache cannot be written.
static WARNED: AtomicBool = AtomicBool::new(false);

fn warn_once(msg: String) {
    if !WARNED.swap(true, Ordering::Relaxed) {
        eprintln!("pprender: warning: {msg}; path banks are kept in memory only");
    }
}

/// What [`prune`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pruned {
    /// Entries removed, and their bytes.
    pub removed: usize,
    pub bytes: u64,
    /// Entries kept (this build's, for any parameters).
    pub kept: usize,
}

/// The code version (bytes) an entry's header names, if it is an entry of this [`FORMAT`]
/// whose header can be read (only the header is read).
fn entry_version(path: &Path) -> Option<Vec<u8>> {
    let mut r = SummedReader {
        inner: BufReader::new(File::open(path).ok()?),
        sum: Checksum::new(),
    };
    read_version(&mut r).ok()
}

/// Remove from `dir` the path-bank entries (`bank-*.ppbank`) that this build can never
/// read: written by another pprender version or layout, or whose header cannot be read
/// (with `all`, every entry), and the temporary files of writers that died. Entries of this
/// build for other parameters are kept: other materials read them. Files that are not
/// entries are never touched; a directory that does not exist holds nothing to remove.
/// Another process still reading a removed entry keeps its open file (POSIX); another
/// pprender version sharing the directory traces its banks again.
pub fn prune(dir: &Path, all: bool) -> io::Result<Pruned> {
    sweep(dir, all, true)
}

/// [`prune`], or with `remove = false` only counting what it would remove (in `removed`
/// and `bytes`).
fn sweep(dir: &Path, all: bool, remove: bool) -> io::Result<Pruned> {
    let mut out = Pruned::default();
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(e),
    };
    if remove {
        sweep_stale_tmp(dir);
    }
    let version = code_version();
    for e in entries {
        let e = e?;
        let name = e.file_name();
        let name = name.to_string_lossy();
        if !(name.starts_with("bank-") && name.ends_with(SUFFIX)) {
            continue;
        }
        let path = e.path();
        if !all && entry_version(&path).as_deref() == Some(version.as_bytes()) {
            out.kept += 1;
            continue;
        }
        let len = e.metadata().map(|m| m.len()).unwrap_or(0);
        if remove {
            match fs::remove_file(&path) {
                Ok(()) => {}
                // removed meanwhile by another process
                Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
                Err(e) => return Err(e),
            }
        }
        out.removed += 1;
        out.bytes += len;
    }
    Ok(out)
}

/// Before the first bank a process traces: say on stderr how much of `dir` this build can
/// never read (entries an older version left; [`prune`] removes them), if any.
fn note_unreadable_once(dir: &Path) {
    static NOTED: AtomicBool = AtomicBool::new(false);
    if NOTED.swap(true, Ordering::Relaxed) {
        return;
    }
    if let Ok(p) = sweep(dir, false, false) {
        if p.removed > 0 {
            eprintln!(
                "pprender: {} path-bank entries ({:.0} MB) in {} are from another pprender \
                 version (or damaged) and are never read; pprender.prune_cache() removes them",
                p.removed,
                p.bytes as f64 / 1e6,
                dir.display()
            );
        }
    }
}

/// Removes the temporary files that processes which died while writing left in `dir`.
fn sweep_stale_tmp(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let name = name.to_string_lossy();
        if !(name.starts_with(".bank-") && name.contains(".tmp-")) {
            continue;
        }
        let old = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age > STALE_TMP);
        if old {
            let _ = fs::remove_file(e.path());
        }
    }
}

/// `spec`'s bank thinned to `cap`: read from the cache directory `dir` when a valid entry
/// is there, else made by `build` (which must trace `spec` and thin to `cap`) and written
/// there for the next process. `dir = None` is no disk cache. An entry that is not valid is
/// reported on stderr, rebuilt and replaced; a directory that cannot be created or written
/// is reported once per process and the bank is returned all the same (a cache problem
/// never fails a material).
pub fn cached(
    dir: Option<&Path>,
    spec: &BankSpec,
    cap: usize,
    build: impl FnOnce() -> Result<PathBank>,
) -> Result<PathBank> {
    let Some(dir) = dir else {
        return build();
    };
    let path = entry_path(dir, spec, cap);
    match PathBank::read_from(&path, spec, cap) {
        Ok(b) => return Ok(b),
        Err(Miss::Absent) => {}
        Err(Miss::Invalid(why)) => eprintln!(
            "pprender: the path-bank cache entry {} is not valid ({why}): tracing it again",
            path.display()
        ),
    }
    note_unreadable_once(dir);
    let bank = build()?;
    if let Err(e) = fs::create_dir_all(dir) {
        warn_once(format!(
            "cannot create the path-bank cache directory {} ({e})",
            dir.display()
        ));
        return Ok(bank);
    }
    sweep_stale_tmp(dir);
    if let Err(e) = bank.write_to(&path, cap) {
        warn_once(format!("cannot write {} ({e})", path.display()));
    }
    Ok(bank)
}

/// Where [`cached`] keeps `spec`'s bank in `dir`.
pub fn entry_path(dir: &Path, spec: &BankSpec, cap: usize) -> PathBuf {
    dir.join(entry_name(spec, cap))
}

#[cfg(test)]
pub(crate) mod tests;
