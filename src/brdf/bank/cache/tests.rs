use super::*;
use std::sync::OnceLock;

/// A small bank (a few thousand rays), thinned so that the weights are not all 1.
const CAP: usize = 150;

fn spec() -> BankSpec {
    BankSpec {
        alpha: 0.7,
        grid: 64,
        correlation_length: 8.0,
        rays: 4000,
        surfaces: 2,
        seed: 5,
        autocorrelation: Default::default(),
    }
}

fn bank() -> &'static PathBank {
    static B: OnceLock<PathBank> = OnceLock::new();
    B.get_or_init(|| {
        let mut b = PathBank::trace(&spec()).unwrap();
        b.thin(CAP);
        b
    })
}

/// A fresh directory under the system's temporary directory, removed on drop.
pub(crate) struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> Self {
        static N: AtomicU64 = AtomicU64::new(0);
        let d = std::env::temp_dir().join(format!(
            "pprender-test-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        TempDir(d)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

const V: &str = "0.1.0+test";

fn invalid(r: std::result::Result<PathBank, Miss>) -> String {
    match r {
        Err(Miss::Invalid(why)) => why,
        Err(Miss::Absent) => panic!("read as absent"),
        Ok(_) => panic!("read as valid"),
    }
}

#[test]
fn the_checksum_does_not_depend_on_how_the_bytes_arrive() {
    let data: Vec<u8> = (0..1000u32).map(|i| (i * 7 + i / 13) as u8).collect();
    let mut whole = Checksum::new();
    whole.update(&data);
    for cut in [1, 3, 8, 9, 500, 999] {
        let mut parts = Checksum::new();
        for c in data.chunks(cut) {
            parts.update(c);
        }
        assert_eq!(parts.finish(), whole.finish(), "chunks of {cut}");
    }
    // any single flipped bit, and a zero byte appended, change it
    for i in [0, 7, 8, 500, 999] {
        for bit in [0, 7] {
            let mut d = data.clone();
            d[i] ^= 1 << bit;
            let mut c = Checksum::new();
            c.update(&d);
            assert_ne!(c.finish(), whole.finish(), "byte {i} bit {bit}");
        }
    }
    let mut c = Checksum::new();
    c.update(&data);
    c.update(&[0]);
    assert_ne!(c.finish(), whole.finish());
}

#[test]
fn a_bank_reads_back_field_by_field() {
    let b = bank();
    assert!(b.weights.iter().flatten().any(|&w| w > 1.0), "thinned");
    assert!(b.paths.iter().flatten().any(|p| !p.is_empty()));
    let dir = TempDir::new("roundtrip");
    let path = dir.0.join(entry_name_for(&b.spec, CAP, V));
    b.write_versioned(&path, CAP, V).unwrap();
    let r = PathBank::read_versioned(&path, &spec(), CAP, V).unwrap();
    assert_eq!(r.spec, b.spec);
    assert_eq!(r.rays, b.rays);
    assert_eq!(r.paths, b.paths);
    assert_eq!(r.albedo, b.albedo);
    assert_eq!(r.truncated, b.truncated);
    assert_eq!(r.lost, b.lost);
    assert_eq!(r.weights, b.weights);
    assert_eq!(&r, b);
    // the public entry points, with this code's version
    let p2 = dir.0.join(entry_name(&b.spec, CAP));
    b.write_to(&p2, CAP).unwrap();
    assert_eq!(&PathBank::read_from(&p2, &spec(), CAP).unwrap(), b);
    // only the entries are left, no temporary files
    let mut names: Vec<String> = fs::read_dir(&dir.0)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names.len(), 2, "{names:?}");
    assert!(names
        .iter()
        .all(|n| n.starts_with("bank-alpha0.7000-") && n.ends_with(SUFFIX)));
}

#[test]
fn a_damaged_or_foreign_file_is_rejected() {
    let b = bank();
    let dir = TempDir::new("reject");
    let path = dir.0.join("entry");
    b.write_versioned(&path, CAP, V).unwrap();
    let good = fs::read(&path).unwrap();
    let read = |bytes: &[u8]| {
        let p = dir.0.join("damaged");
        fs::write(&p, bytes).unwrap();
        PathBank::read_versioned(&p, &spec(), CAP, V)
    };
    assert_eq!(&read(&good).unwrap(), b);
    assert_eq!(
        PathBank::read_versioned(&dir.0.join("none"), &spec(), CAP, V).unwrap_err(),
        Miss::Absent
    );
    let n = good.len();
    let header = fixed_header_len(V.len() as u64) as usize + NODE_RECORD as usize * N_THETA;
    assert!(n > header + 8 + 1000);
    // truncated anywhere: in the magic, the header, the data, the checksum
    for cut in [
        0,
        5,
        8,
        40,
        header - 3,
        header + 8,
        n / 2,
        n - 9,
        n - 8,
        n - 1,
    ] {
        let why = invalid(read(&good[..cut]));
        assert!(
            why.contains("early") || why.contains("bytes"),
            "cut {cut}: {why}"
        );
    }
    // one flipped byte anywhere: magic, format, version, spec, albedos, data, checksum
    for at in [
        0,
        9,
        17,
        40,
        80,
        header - 1,
        header + 5,
        n / 2,
        n - 20,
        n - 1,
    ] {
        let mut d = good.clone();
        d[at] ^= 0x10;
        invalid(read(&d));
    }
    // a length field made absurd: refused before anything is allocated
    let lens_at =
        fixed_header_len(V.len() as u64) as usize + NODE_RECORD as usize - 8 * (MAX_ORDER - 1);
    for absurd in [4u64 << 40, u64::MAX - 3] {
        let mut d = good.clone();
        d[lens_at..lens_at + 8].copy_from_slice(&absurd.to_le_bytes());
        let why = invalid(read(&d));
        assert!(
            why.contains("lengths") || why.contains("whole paths"),
            "{why}"
        );
    }
    // a byte appended
    let mut d = good.clone();
    d.push(0);
    invalid(read(&d));
    // another spec, cap or version: never found under its name, and rejected if read
    let p = dir.0.join("entry");
    for other in [
        BankSpec {
            alpha: 0.8,
            ..spec()
        },
        BankSpec {
            grid: 128,
            ..spec()
        },
        BankSpec {
            correlation_length: 9.0,
            ..spec()
        },
        BankSpec {
            rays: 4001,
            ..spec()
        },
        BankSpec {
            surfaces: 3,
            ..spec()
        },
        BankSpec { seed: 6, ..spec() },
    ] {
        assert_ne!(
            entry_name_for(&other, CAP, V),
            entry_name_for(&spec(), CAP, V)
        );
        let why = invalid(PathBank::read_versioned(&p, &other, CAP, V));
        assert!(why.contains("a bank for"), "{why}");
    }
    assert_ne!(
        entry_name_for(&spec(), CAP + 1, V),
        entry_name_for(&spec(), CAP, V)
    );
    invalid(PathBank::read_versioned(&p, &spec(), CAP + 1, V));
    assert_ne!(
        entry_name_for(&spec(), CAP, "0.1.1"),
        entry_name_for(&spec(), CAP, V)
    );
    let why = invalid(PathBank::read_versioned(&p, &spec(), CAP, "0.1.1"));
    assert!(why.contains("stale"), "{why}");
    // this code's version names the crate's
    assert!(code_version().starts_with(concat!(env!("CARGO_PKG_VERSION"), "+")));
}

/// Builders of the same entry at once (threads here; processes alike: each writes its own
/// temporary file and renames it) leave a valid entry and no temporary file.
#[test]
fn concurrent_writers_leave_a_valid_entry() {
    let b = bank();
    let dir = TempDir::new("concurrent");
    let path = dir.0.join(entry_name_for(&b.spec, CAP, V));
    std::thread::scope(|s| {
        for _ in 0..4 {
            s.spawn(|| {
                for _ in 0..3 {
                    b.write_versioned(&path, CAP, V).unwrap();
                    // a reader in the meantime sees a whole entry
                    assert_eq!(
                        &PathBank::read_versioned(&path, &spec(), CAP, V).unwrap(),
                        b
                    );
                }
            });
        }
    });
    assert_eq!(
        &PathBank::read_versioned(&path, &spec(), CAP, V).unwrap(),
        b
    );
    assert_eq!(fs::read_dir(&dir.0).unwrap().count(), 1);
}

/// [`prune`] removes what this build can never read (another version's entry, a file with
/// a damaged header, an old temporary file) and keeps this build's entries, for any
/// parameters, and files that are not entries; with `all` it removes this build's entries
/// too. A directory that does not exist holds nothing to remove.
#[test]
fn prune_removes_what_this_build_cannot_read() {
    let b = bank();
    let dir = TempDir::new("prune");
    let d = &dir.0;
    let current = d.join(entry_name(&b.spec, CAP));
    b.write_to(&current, CAP).unwrap();
    let other_cap = d.join(entry_name(&b.spec, CAP + 1));
    b.write_to(&other_cap, CAP + 1).unwrap();
    let foreign = d.join(entry_name_for(&b.spec, CAP, V));
    b.write_versioned(&foreign, CAP, V).unwrap();
    let damaged = d.join("bank-alpha0.7000-0123456789abcdef.ppbank");
    let junk = b"PPRBANK\nnot a header";
    fs::write(&damaged, junk).unwrap();
    let other = d.join("notes.txt");
    fs::write(&other, b"mine").unwrap();
    let tmp = d.join(".bank-alpha0.7000-x.ppbank.tmp-1-1");
    fs::write(&tmp, b"half").unwrap();
    let old = SystemTime::now() - 2 * STALE_TMP;
    File::options()
        .write(true)
        .open(&tmp)
        .unwrap()
        .set_modified(old)
        .unwrap();
    let foreign_len = fs::metadata(&foreign).unwrap().len();
    // counting only (the notice before a process's first trace) removes nothing
    let counted = sweep(d, false, false).unwrap();
    assert_eq!((counted.removed, counted.kept), (2, 2));
    assert!(foreign.exists() && damaged.exists() && tmp.exists());
    let p = prune(d, false).unwrap();
    assert_eq!(
        p,
        Pruned {
            removed: 2,
            bytes: foreign_len + junk.len() as u64,
            kept: 2
        }
    );
    for (f, there) in [
        (&current, true),
        (&other_cap, true),
        (&foreign, false),
        (&damaged, false),
        (&other, true),
        (&tmp, false),
    ] {
        assert_eq!(f.exists(), there, "{}", f.display());
    }
    assert_eq!(&PathBank::read_from(&current, &spec(), CAP).unwrap(), b);
    let p = prune(d, true).unwrap();
    assert_eq!((p.removed, p.kept), (2, 0));
    assert!(!current.exists() && !other_cap.exists() && other.exists());
    assert_eq!(prune(&d.join("absent"), true).unwrap(), Pruned::default());
}
