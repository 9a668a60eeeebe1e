//! What a run may take from the machine: the memory budget (`--max-memory`), the size of the
//! files it reads, and the estimate of a mesh's size made from the inputs and the settings before
//! anything large is allocated.

use crate::config::MeshConfig;
use crate::error::{Error, Result};
use crate::input::Centerlines;
use std::path::Path;

/// Share of the machine's memory a run may plan to use by default.
const DEFAULT_SHARE: f64 = 0.75;

/// Budget when the machine's memory cannot be read.
const FALLBACK_BYTES: u64 = 8 << 30;

/// The default `--max-memory`: three quarters of the machine's memory (or of the control
/// group's limit, when it is lower).
pub fn default_max_memory() -> u64 {
    match machine_memory() {
        Some(m) => (m as f64 * DEFAULT_SHARE) as u64,
        None => FALLBACK_BYTES,
    }
}

/// Physical memory (Linux: `MemTotal`), or the cgroup's limit when lower.
fn machine_memory() -> Option<u64> {
    let total = meminfo("MemTotal:")?;
    let limit = CGROUP_FILES.iter().filter_map(|(limit, _)| read_number(limit)).min();
    Some(limit.map_or(total, |l| l.min(total)))
}

/// The memory the machine can give now without swapping (Linux: `MemAvailable`), or the
/// room left under the cgroup's limit when less.
pub fn available_memory() -> Option<u64> {
    let available = meminfo("MemAvailable:")?;
    let room = CGROUP_FILES
        .iter()
        .filter_map(|(limit, usage)| Some(read_number(limit)?.saturating_sub(read_number(usage)?)))
        .min();
    Some(room.map_or(available, |r| r.min(available)))
}

/// The cgroup's memory limit and usage files (v2, then v1).
const CGROUP_FILES: [(&str, &str); 2] = [
    ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
    ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
];

/// A line of /proc/meminfo, in bytes.
fn meminfo(key: &str) -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kib: u64 = text.lines().find(|l| l.starts_with(key))?.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

fn read_number(path: &str) -> Option<u64> {
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

/// Parses a size: a number of bytes with an optional binary suffix, `K`, `M`, `G` or `T` (`KiB`,
/// `GB`... read alike): `8G`, `512M`, `1.5G`.
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let shift = match unit.trim().to_ascii_uppercase().trim_end_matches("IB").trim_end_matches('B') {
        "" => 0,
        "K" => 10,
        "M" => 20,
        "G" => 30,
        "T" => 40,
        _ => return Err(format!("'{text}' is not a size; use e.g. 8G, 512M or 2T")),
    };
    match number.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x * ((1u64 << shift) as f64) < 1.8e19 => {
            Ok((x * (1u64 << shift) as f64) as u64)
        }
        _ => Err(format!("'{text}' is not a positive size; use e.g. 8G, 512M or 2T")),
    }
}

/// A size for messages: "1.5 GiB".
pub fn show_bytes(bytes: f64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut x = bytes;
    let mut u = 0;
    while x >= 1024.0 && u + 1 < units.len() {
        x /= 1024.0;
        u += 1;
    }
    if x.is_finite() {
        format!("{x:.1} {}", units[u])
    } else {
        "more than any machine has".into()
    }
}

/// A number for messages: four significant digits, in exponent form when very small or large.
pub fn short(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || (1e-3..1e6).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        let text = format!("{x:.digits$}");
        let text = if text.contains('.') { text.trim_end_matches('0').trim_end_matches('.').to_string() } else { text };
        text
    } else {
        format!("{x:.3e}")
    }
}

/// Largest input file read, as a share of the memory budget: a surface takes about nine times
/// its binary STL size once read and indexed (measured: 2.0 million triangles, 100 MB, took
/// 864 MB).
pub const FILE_SHARE: u64 = 10;

/// The limits of the files a run reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// Largest file read.
    pub file_bytes: u64,
    /// Largest total of a file's compressed arrays once inflated.
    pub inflated_bytes: u64,
}

impl ReadLimits {
    /// The limits under a memory budget.
    pub fn within(max_memory: u64) -> ReadLimits {
        ReadLimits { file_bytes: max_memory / FILE_SHARE, inflated_bytes: max_memory / FILE_SHARE }
    }
}

impl Default for ReadLimits {
    fn default() -> Self {
        ReadLimits::within(default_max_memory())
    }
}

/// Bytes per hexahedron at the peak of a run (the mesh, its annotation, its quality figures and
/// the writers), measured with `/usr/bin/time -f %M`: an unbranched vessel 1.36 kB (405,060
/// hexes, 561 MB, fine preset with a finer axial spacing; every format: 550 MB), a branched one
/// 2.2 kB (the Y fixture, 459,240 hexes, 1.0 GB) to 3.5 kB (gmsh_aortic_arch at medium, whose
/// junction is finished in up to twenty ways kept side by side).
const BYTES_PER_HEX: f64 = 1600.0;
const BYTES_PER_HEX_BRANCHED: f64 = 4000.0;

/// Bytes per surface triangle once read and indexed (measured: 2.0 million triangles, 864 MB).
const BYTES_PER_TRIANGLE: f64 = 450.0;

/// Bytes per centerline sample (points, radii, frames and the smoothing's copies).
const BYTES_PER_SAMPLE: f64 = 400.0;

/// What a run holds besides the mesh (program, thread stacks, buffers).
const BASE_BYTES: f64 = 32e6;

/// Largest number of nodes a mesh may have (node numbers are 32-bit in the mesh and the decks).
const MAX_NODES: f64 = 2.0e9;

/// A mesh's size, estimated from the centerlines and the settings before it is built.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshEstimate {
    /// Cross-sections along the vessel (paths drawn twice, as VMTK's overlapping inlet-to-outlet
    /// paths are, counted once).
    pub sections: f64,
    /// Centerline samples (resampling step `centerline.resample_step` times the radius).
    pub samples: f64,
    pub hexes: f64,
    pub nodes: f64,
    pub bytes: f64,
    /// The stretch that contributes most sections, for the message: the polyline, the points
    /// and the sections it alone makes.
    pub densest: Option<(usize, usize, f64)>,
    pub median_radius: f64,
    pub length: f64,
}

/// Estimates the mesh of `centerlines` (lengths in mm, radii per point or `radius` throughout)
/// with `config` on a surface of `triangles` triangles.
pub fn estimate_mesh(centerlines: &Centerlines, radius: f64, config: &MeshConfig, triangles: usize) -> MeshEstimate {
    let l = &config.lumen;
    let n = l.core_elements as f64;
    let ring = 4.0 * n;
    let wall: usize =
        [&config.wall.intima, &config.wall.media, &config.wall.adventitia].iter().map(|x| x.elements).sum();
    let per_section = n * n + ring * l.radial_elements as f64 + ring * wall as f64;
    let nodes_per_section = (n + 1.0) * (n + 1.0) + ring * (l.radial_elements + wall) as f64;
    let spacing = |r: f64| l.axial_spacing_mm.unwrap_or(l.axial_spacing * r);
    let mut seen = SeenPoints::new(radius);
    let (mut sections, mut samples, mut length) = (0.0, 0.0, 0.0);
    let mut densest: Option<(usize, usize, f64)> = None;
    for (k, line) in centerlines.polylines.iter().enumerate() {
        let r_at = |i: usize| line.radii.as_ref().map_or(radius, |r| r[i]).max(0.1 * radius);
        let mut line_length = 0.0;
        for i in 1..line.points.len() {
            let d = (line.points[i] - line.points[i - 1]).norm();
            let r = 0.5 * (r_at(i) + r_at(i - 1));
            line_length += d;
            if seen.holds(&line.points[i], r) {
                continue;
            }
            let s = d / spacing(r);
            sections += s;
            if densest.is_none_or(|(_, _, most)| s > most) {
                densest = Some((k, i, s));
            }
        }
        // Added after the polyline, whose own points are always new.
        line.points.iter().for_each(|p| seen.add(p));
        length += line_length;
        samples += line_length / (config.centerline.resample_step * radius);
    }
    let branched = centerlines.polylines.len() > 1;
    let hexes = sections * per_section;
    let nodes = (sections + centerlines.polylines.len() as f64) * nodes_per_section;
    let per_hex = if branched { BYTES_PER_HEX_BRANCHED } else { BYTES_PER_HEX };
    let bytes = BASE_BYTES + triangles as f64 * BYTES_PER_TRIANGLE + samples * BYTES_PER_SAMPLE + hexes * per_hex;
    MeshEstimate { sections, samples, hexes, nodes, bytes, densest, median_radius: radius, length }
}

/// Points already counted, on a grid of cells a radius wide: a point within half a radius of
/// one of them lies on a path counted before (VMTK's paths share their common trunk).
struct SeenPoints {
    cell: f64,
    grid: std::collections::HashMap<[i64; 3], Vec<nalgebra::Point3<f64>>>,
    /// Past this many points the paths are not compared any more (they count in full).
    room: usize,
}

impl SeenPoints {
    fn new(radius: f64) -> SeenPoints {
        SeenPoints { cell: radius.max(1e-9), grid: Default::default(), room: 2_000_000 }
    }

    fn key(&self, p: &nalgebra::Point3<f64>) -> Option<[i64; 3]> {
        let k = p.coords.map(|c| (c / self.cell).floor());
        k.iter().all(|c| c.abs() < 1e15).then(|| [k.x as i64, k.y as i64, k.z as i64])
    }

    /// Whether `p` lies within half the radius `r` of a point added before.
    fn holds(&self, p: &nalgebra::Point3<f64>, r: f64) -> bool {
        let Some(key) = self.key(p) else { return false };
        let near = 0.5 * r.min(self.cell);
        (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    let k = [key[0] + dx, key[1] + dy, key[2] + dz];
                    self.grid.get(&k).is_some_and(|pts| pts.iter().any(|q| (q - p).norm() < near))
                })
            })
        })
    }

    fn add(&mut self, p: &nalgebra::Point3<f64>) {
        if let (Some(key), true) = (self.key(p), self.room > 0) {
            self.room -= 1;
            self.grid.entry(key).or_default().push(*p);
        }
    }
}

/// The vessel's median radius: the centerline's radii, or where the file has none (gmsh's
/// segments), the distance from points along it to the nearest surface vertex.
pub fn median_radius(centerlines: &Centerlines, surface: &crate::input::TriangleSurface) -> f64 {
    let mut radii: Vec<f64> = centerlines.polylines.iter().flat_map(|l| l.radii.iter().flatten().copied()).collect();
    if radii.is_empty() {
        let points: Vec<_> = centerlines.polylines.iter().flat_map(|l| l.points.iter()).collect();
        let step = (points.len() / 64).max(1);
        radii = points
            .iter()
            .step_by(step)
            .map(|p| surface.vertices.iter().map(|v| (v - *p).norm()).fold(f64::INFINITY, f64::min))
            .collect();
    }
    radii.retain(|r| r.is_finite());
    radii.sort_by(f64::total_cmp);
    radii.get(radii.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Refuses a mesh that would not fit in `max_memory` (or whose node numbers would not fit in 32
/// bits), naming the estimate, what drives it and the settings to change.
pub fn check_fits(estimate: &MeshEstimate, max_memory: u64, centerline_source: &Path) -> Result<()> {
    let e = estimate;
    if e.bytes <= max_memory as f64 && e.nodes <= MAX_NODES && e.bytes.is_finite() {
        return Ok(());
    }
    let driver = match e.densest {
        Some((line, point, sections)) if sections > 0.5 * e.sections && e.sections > 1e3 => format!(
            "; the step to point {point} of polyline {line} alone makes {} of them (a mistyped point or radius?)",
            count(sections)
        ),
        _ => String::new(),
    };
    let limit = if e.nodes > MAX_NODES {
        format!("more than the {} nodes a mesh may have", count(MAX_NODES))
    } else {
        format!("more than --max-memory {}", show_bytes(max_memory as f64))
    };
    Err(Error::input(
        centerline_source,
        format!(
            "the mesh would need about {} ({} hexahedra, {} nodes, {} cross-sections along {} mm of centerline \
             with a median radius of {} mm{driver}), {limit}: check the centerline's points, radii and units, \
             or coarsen the mesh (lumen.axial_spacing, lumen.core_elements, lumen.radial_elements, the wall \
             layers' elements), or raise --max-memory",
            show_bytes(e.bytes),
            count(e.hexes),
            count(e.nodes),
            count(e.sections),
            count(e.length),
            short(e.median_radius)
        ),
    ))
}

/// A count for messages: "1.2e12" beyond a billion, else with digits grouped.
fn count(x: f64) -> String {
    if !x.is_finite() || x >= 1e9 {
        format!("{x:.1e}")
    } else {
        let digits = format!("{:.0}", x);
        let mut out = String::new();
        for (i, c) in digits.chars().enumerate() {
            if i > 0 && (digits.len() - i).is_multiple_of(3) {
                out.push(',');
            }
            out.push(c);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_binary_suffixes() {
        assert_eq!(parse_size("512M").unwrap(), 512 << 20);
        assert_eq!(parse_size("8G").unwrap(), 8 << 30);
        assert_eq!(parse_size("8GiB").unwrap(), 8 << 30);
        assert_eq!(parse_size("1.5g").unwrap(), 3 << 29);
        assert_eq!(parse_size("4096").unwrap(), 4096);
        for bad in ["", "G", "-1G", "8X", "1e30T", "nan"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn short_numbers_keep_four_digits() {
        assert_eq!(short(10.0), "10");
        assert_eq!(short(1.4589e-3), "0.001459");
        assert_eq!(short(12345.678), "12346");
        assert_eq!(short(1e-9), "1.000e-9");
        assert_eq!(short(-2.5), "-2.5");
        assert_eq!(short(0.0), "0");
    }

    #[test]
    fn counts_group_their_digits() {
        assert_eq!(count(1234567.0), "1,234,567");
        assert_eq!(count(999.0), "999");
        assert_eq!(count(3.2e12), "3.2e12");
    }
}
