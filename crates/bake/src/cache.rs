//! On-disk cache of baked grids: one small little-endian file per (mesh content, resolution,
//! format version).
//!
//! Layout (all little-endian):
//!
//! | bytes | field |
//! |---|---|
//! | 8 | magic `b"MMSDFGRD"` |
//! | 4 | format version (u32, [`FORMAT_VERSION`]) |
//! | 8 | mesh content hash (u64, `TriangleMesh::content_hash`) |
//! | 4 | resolution (u32) |
//! | 12 | dims (3 x u32) |
//! | 12 | min (3 x f32) |
//! | 4 | cell size (f32) |
//! | 8 | value count (u64) = dims product |
//! | 4 x count | values (f32) |
//! | 8 | FNV-1a 64 of every preceding byte |
//!
//! Sparse grids ([`encode_sparse`]) are another file kind, `<hash>-r<res>-b<band>-<quant>-<recon>-v<version>.sdfbricks`:
//!
//! | bytes | field |
//! |---|---|
//! | 8 | magic `b"MMSDFBRK"` |
//! | 4 | format version (u32, [`SPARSE_FORMAT_VERSION`]) |
//! | 8 | mesh content hash (u64) |
//! | 4 | resolution (u32) |
//! | 4 | band voxels (u32) |
//! | 1 + 1 | quantization code, reconstruction code |
//! | 12 | brick cells per axis (3 x u32) |
//! | 12 | min (3 x f32) |
//! | 4 | cell size (f32) |
//! | 4 | clamp (f32) |
//! | 8 | brick count (u64) |
//! | 4 x cells | brick-cell words (u32) |
//! | bytes x samples | brick samples (f32, u16 or u8) |
//! | 2 x samples | octahedral normal codes (u16), `normals` reconstruction only |
//! | 8 | FNV-1a 64 of every preceding byte |
//!
//! and are validated as fully: key, sizes, checksum, then every invariant of
//! [`SparseGrid::from_parts`] (each brick referenced exactly once, finite samples).
//!
//! Files are written to a unique temporary name in the same directory and renamed into
//! place, so readers never see a partial file. Any mismatch on read (short file, magic,
//! version, key, dims, length, non-finite header, checksum) makes the caller re-bake.

use std::io::Write;
use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::SparseOptions;
use crate::grid::DistanceGrid;
use crate::sparse::{Quantization, Reconstruction, Samples, SparseGrid};

/// Cache format version; bump when the file layout or the bake algorithm (padding, sign
/// rule, far-field parameters) changes, so stale files are re-baked.
pub const FORMAT_VERSION: u32 = 1;

const MAGIC: &[u8; 8] = b"MMSDFGRD";
const HEADER: usize = 8 + 4 + 8 + 4 + 12 + 12 + 4 + 8;

/// The cache file for `(hash, resolution)` under `dir`.
pub fn cache_path(dir: &Path, hash: u64, resolution: u32) -> PathBuf {
    dir.join(format!(
        "{hash:016x}-r{resolution}-v{FORMAT_VERSION}.sdfgrid"
    ))
}

/// Sparse cache format version; bump when the layout or the sparse bake (band rule, sign
/// rule, clamp) changes. 4: normal codes of the `normals` reconstruction.
pub const SPARSE_FORMAT_VERSION: u32 = 4;

const SPARSE_MAGIC: &[u8; 8] = b"MMSDFBRK";
const SPARSE_HEADER: usize = 8 + 4 + 8 + 4 + 4 + 2 + 12 + 12 + 4 + 4 + 8;

/// The cache file of a sparse grid baked from the mesh with content `hash` with `opts`.
pub fn sparse_cache_path(dir: &Path, hash: u64, opts: &SparseOptions) -> PathBuf {
    dir.join(format!(
        "{hash:016x}-r{}-b{}-{}-{}-v{SPARSE_FORMAT_VERSION}.sdfbricks",
        opts.resolution,
        opts.band_voxels,
        opts.quantization.name(),
        opts.reconstruction.name()
    ))
}

/// Serialises a sparse grid with its key.
pub fn encode_sparse(grid: &SparseGrid, hash: u64, opts: &SparseOptions) -> Vec<u8> {
    let mut b =
        Vec::with_capacity(SPARSE_HEADER + grid.cells().len() * 4 + grid.samples().bytes() + 8);
    b.extend_from_slice(SPARSE_MAGIC);
    b.extend_from_slice(&SPARSE_FORMAT_VERSION.to_le_bytes());
    b.extend_from_slice(&hash.to_le_bytes());
    b.extend_from_slice(&opts.resolution.to_le_bytes());
    b.extend_from_slice(&grid.band_voxels().to_le_bytes());
    b.push(grid.samples().quantization().code());
    b.push(grid.reconstruction().code());
    for d in grid.bricks() {
        b.extend_from_slice(&d.to_le_bytes());
    }
    for c in grid.min().to_array() {
        b.extend_from_slice(&c.to_le_bytes());
    }
    b.extend_from_slice(&grid.cell_size().to_le_bytes());
    b.extend_from_slice(&grid.clamp().to_le_bytes());
    b.extend_from_slice(&(grid.brick_count() as u64).to_le_bytes());
    for w in grid.cells() {
        b.extend_from_slice(&w.to_le_bytes());
    }
    match grid.samples() {
        Samples::F32(v) => v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes())),
        Samples::U16(v) => v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes())),
        Samples::U8(v) => b.extend_from_slice(v),
    }
    for n in grid.normals() {
        b.extend_from_slice(&n.to_le_bytes());
    }
    let mut h = Fnv::new();
    h.write(&b);
    b.extend_from_slice(&h.0.to_le_bytes());
    b
}

/// Parses and validates a sparse cache file against the expected key (`hash` and the
/// options that shape the grid). `Err` explains the first problem found.
pub fn decode_sparse(bytes: &[u8], hash: u64, opts: &SparseOptions) -> Result<SparseGrid, String> {
    let mut r = Reader { b: bytes, at: 0 };
    if &r.take::<8>()? != SPARSE_MAGIC {
        return Err("bad magic".into());
    }
    let v = r.u32()?;
    if v != SPARSE_FORMAT_VERSION {
        return Err(format!(
            "format version {v}, expected {SPARSE_FORMAT_VERSION}"
        ));
    }
    let h = r.u64()?;
    if h != hash {
        return Err(format!("mesh hash {h:016x}, expected {hash:016x}"));
    }
    let res = r.u32()?;
    if res != opts.resolution {
        return Err(format!("resolution {res}, expected {}", opts.resolution));
    }
    let band = r.u32()?;
    if band != opts.band_voxels {
        return Err(format!("band {band}, expected {}", opts.band_voxels));
    }
    let [qc, rc] = r.take::<2>()?;
    let q = Quantization::from_code(qc).ok_or("unknown quantization")?;
    let recon = Reconstruction::from_code(rc).ok_or("unknown reconstruction")?;
    if q != opts.quantization || recon != opts.reconstruction {
        return Err(format!(
            "{} {} grid, expected {} {}",
            q.name(),
            recon.name(),
            opts.quantization.name(),
            opts.reconstruction.name()
        ));
    }
    let bricks = [r.u32()?, r.u32()?, r.u32()?];
    if bricks.iter().any(|&d| d == 0 || d > 1 << 12) {
        return Err(format!("bad brick cell counts {bricks:?}"));
    }
    let min = Vec3::new(r.f32()?, r.f32()?, r.f32()?);
    let cell = r.f32()?;
    let clamp = r.f32()?;
    let count = r.u64()?;
    let n_cells: usize = bricks.iter().map(|&d| d as usize).product();
    let edge = (crate::sparse::BRICK + 1 + 2 * recon.apron()) as u64;
    let samples = usize::try_from(count)
        .ok()
        .and_then(|c| c.checked_mul(edge.pow(3) as usize))
        .filter(|&s| s <= n_cells.saturating_mul(edge.pow(3) as usize))
        .ok_or("brick count too large")?;
    let normal_codes = if recon == Reconstruction::Normals {
        samples
    } else {
        0
    };
    let body = n_cells * 4 + samples * q.bytes() + normal_codes * 2;
    if bytes.len() != SPARSE_HEADER + body + 8 {
        return Err(format!(
            "file is {} bytes, expected {}",
            bytes.len(),
            SPARSE_HEADER + body + 8
        ));
    }
    let mut f = Fnv::new();
    f.write(&bytes[..SPARSE_HEADER + body]);
    let stored = u64::from_le_bytes(
        bytes[SPARSE_HEADER + body..]
            .try_into()
            .map_err(|_| "truncated checksum")?,
    );
    if stored != f.0 {
        return Err("checksum mismatch".into());
    }
    let cells_end = SPARSE_HEADER + n_cells * 4;
    let cells: Vec<u32> = bytes[SPARSE_HEADER..cells_end]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let samples_end = cells_end + samples * q.bytes();
    let raw = &bytes[cells_end..samples_end];
    let normals: Vec<u16> = bytes[samples_end..SPARSE_HEADER + body]
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    let samples = match q {
        Quantization::F32 => Samples::F32(
            raw.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        ),
        Quantization::U16 => Samples::U16(
            raw.chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect(),
        ),
        Quantization::U8 => Samples::U8(raw.to_vec()),
    };
    SparseGrid::from_parts(
        min, cell, bricks, band, clamp, recon, cells, samples, normals,
    )
}

struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// Serialises `grid` with its key.
pub fn encode(grid: &DistanceGrid, hash: u64, resolution: u32) -> Vec<u8> {
    let mut b = Vec::with_capacity(HEADER + grid.values.len() * 4 + 8);
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    b.extend_from_slice(&hash.to_le_bytes());
    b.extend_from_slice(&resolution.to_le_bytes());
    for d in grid.dims {
        b.extend_from_slice(&d.to_le_bytes());
    }
    for c in grid.min.to_array() {
        b.extend_from_slice(&c.to_le_bytes());
    }
    b.extend_from_slice(&grid.cell_size.to_le_bytes());
    b.extend_from_slice(&(grid.values.len() as u64).to_le_bytes());
    for v in &grid.values {
        b.extend_from_slice(&v.to_le_bytes());
    }
    let mut h = Fnv::new();
    h.write(&b);
    b.extend_from_slice(&h.0.to_le_bytes());
    b
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let s = self
            .b
            .get(self.at..self.at + N)
            .ok_or_else(|| format!("truncated at byte {}", self.at))?;
        self.at += N;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    fn u32(&mut self) -> Result<u32, String> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> Result<u64, String> {
        self.take::<8>().map(u64::from_le_bytes)
    }
    fn f32(&mut self) -> Result<f32, String> {
        self.take::<4>().map(f32::from_le_bytes)
    }
}

/// Parses and validates a cache file's bytes against the expected key. `Err` explains the
/// first problem found.
pub fn decode(bytes: &[u8], hash: u64, resolution: u32) -> Result<DistanceGrid, String> {
    let mut r = Reader { b: bytes, at: 0 };
    if &r.take::<8>()? != MAGIC {
        return Err("bad magic".into());
    }
    let v = r.u32()?;
    if v != FORMAT_VERSION {
        return Err(format!("format version {v}, expected {FORMAT_VERSION}"));
    }
    let h = r.u64()?;
    if h != hash {
        return Err(format!("mesh hash {h:016x}, expected {hash:016x}"));
    }
    let res = r.u32()?;
    if res != resolution {
        return Err(format!("resolution {res}, expected {resolution}"));
    }
    let dims = [r.u32()?, r.u32()?, r.u32()?];
    if dims.iter().any(|&d| d < 2) {
        return Err(format!("bad dims {dims:?}"));
    }
    let min = Vec3::new(r.f32()?, r.f32()?, r.f32()?);
    let cell = r.f32()?;
    if !min.is_finite() || !cell.is_finite() || cell <= 0.0 {
        return Err("non-finite or non-positive grid header".into());
    }
    let count = r.u64()?;
    let expect = dims.iter().map(|&d| d as u64).product::<u64>();
    if count != expect {
        return Err(format!("value count {count}, dims {dims:?} need {expect}"));
    }
    let body = usize::try_from(count)
        .ok()
        .and_then(|c| c.checked_mul(4))
        .ok_or("value count too large")?;
    if bytes.len() != HEADER + body + 8 {
        return Err(format!(
            "file is {} bytes, expected {}",
            bytes.len(),
            HEADER + body + 8
        ));
    }
    let mut f = Fnv::new();
    f.write(&bytes[..HEADER + body]);
    let stored = u64::from_le_bytes(
        bytes[HEADER + body..]
            .try_into()
            .map_err(|_| "truncated checksum")?,
    );
    if stored != f.0 {
        return Err("checksum mismatch".into());
    }
    let values: Vec<f32> = bytes[HEADER..HEADER + body]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if values.iter().any(|v| v.is_nan()) {
        return Err("NaN sample".into());
    }
    Ok(DistanceGrid {
        min,
        cell_size: cell,
        dims,
        values,
    })
}

/// Reads and decodes the cached grid at `file`: `Some` when it is there and valid; otherwise
/// `None`, with a note saying why it was not used (none when the file does not exist).
/// `what` names the grid kind in the notes.
pub(crate) fn read_cached<T>(
    file: &Path,
    what: &str,
    decode: impl FnOnce(&[u8]) -> Result<T, String>,
    notes: &mut Vec<String>,
) -> Option<T> {
    // A regular file within the read cap only: a cache file linked to /dev/zero or a FIFO is
    // rejected without reading (or blocking).
    match marchmesh_safeio::read_regular(file) {
        Ok(bytes) => match decode(&bytes) {
            Ok(grid) => return Some(grid),
            Err(why) => notes.push(format!(
                "{what} cache file {} rejected ({why}); re-baked",
                file.display()
            )),
        },
        // No file, or the cache folder is not a folder (said once, when writing).
        Err(marchmesh_safeio::SafeIoError::Io { source, .. })
            if matches!(
                source.kind(),
                std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
            ) => {}
        Err(e) => notes.push(format!("{what} cache file rejected ({e}); re-baked")),
    }
    None
}

/// Writes `bytes` to `file` ([`write_atomic`]) and notes the outcome; a failure to cache is
/// never an error (the grid is still returned).
pub(crate) fn write_cached(file: &Path, what: &str, bytes: &[u8], notes: &mut Vec<String>) {
    match write_atomic(file, bytes) {
        Ok(()) => notes.push(format!("{what} cached as {}", file.display())),
        Err(e) => notes.push(format!("could not cache {what} at {}: {e}", file.display())),
    }
}

/// Writes `bytes` to `path` atomically (unique temp file in the same directory, then
/// rename). Creates the directory if needed; when it, or a folder above it, is a file or a
/// dangling symbolic link, the error names which.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    marchmesh_safeio::create_folder(dir).map_err(std::io::Error::other)?;
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.{nanos}.tmp", std::process::id()));
    write_via(path, &tmp, bytes)
}

/// Writes `bytes` to the new file `tmp` and renames it to `path`. `tmp` is created new
/// (never opened if anything, a symbolic link included, is already there: a link planted at
/// the name in a shared cache folder is not written through); on failure it is removed only
/// if this call created it.
fn write_via(path: &Path, tmp: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(tmp)?;
    let res = (|| {
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(tmp, path)
    })();
    drop(f);
    if res.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    res
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_link_planted_at_the_temporary_name_is_not_written_through() {
        let dir = std::env::temp_dir().join(format!("bake-cache-link-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let victim = dir.join("victim");
        std::fs::write(&victim, b"precious").unwrap();
        let tmp = dir.join(".grid.tmp");
        std::os::unix::fs::symlink(&victim, &tmp).unwrap();
        let target = dir.join("grid.sdfgrid");
        assert!(write_via(&target, &tmp, b"grid").is_err());
        assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
        assert!(
            std::fs::symlink_metadata(&tmp)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert!(!target.exists());
        write_atomic(&target, b"grid").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"grid");
        // A cache folder that is a file is named as one, not as "File exists".
        let e = write_atomic(&victim.join("grid.sdfgrid"), b"grid").unwrap_err();
        assert!(e.to_string().contains("is a file, not a folder"), "{e}");
        assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn grid() -> DistanceGrid {
        DistanceGrid {
            min: Vec3::new(-1.0, 0.5, 2.0),
            cell_size: 0.25,
            dims: [2, 3, 2],
            values: (0..12).map(|i| i as f32 - 5.5).collect(),
        }
    }

    #[test]
    fn round_trip_and_every_corruption_detected() {
        let g = grid();
        let b = encode(&g, 42, 7);
        assert_eq!(decode(&b, 42, 7).unwrap(), g);
        assert!(decode(&b, 43, 7).unwrap_err().contains("hash"));
        assert!(decode(&b, 42, 8).unwrap_err().contains("resolution"));
        assert!(decode(&b[..b.len() - 1], 42, 7).is_err());
        assert!(decode(&[], 42, 7).is_err());
        // Flip each byte in turn: every single-byte corruption is caught.
        for i in 0..b.len() {
            let mut c = b.clone();
            c[i] ^= 0x10;
            assert!(decode(&c, 42, 7).is_err(), "byte {i}");
        }
        let mut longer = b.clone();
        longer.push(0);
        assert!(decode(&longer, 42, 7).is_err());
    }
}
