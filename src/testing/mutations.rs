//! Every real vessel written the ways users' tools write it (issue 45): the mutation suite's
//! inputs. A cohort case's surface ([`Base`]) is written once per [`Mutation`] into a folder,
//! with the arguments `vesselhex mesh` needs to read it ([`Written`]); [`super::suite`] meshes
//! them and judges each against the case as given.
//!
//! Everything random is seeded by the case's and the mutation's names, so a run repeats.

use super::decimate::decimate;
use crate::centerline_extract::{extract_centerlines, find_caps, EndKind, ExtractOptions, Extraction};
use crate::input::topology::{boundary_loops, loop_centre_and_area, orient_consistently, triangle_neighbours};
use crate::input::{clean_surface, read_surface, weld, TriangleSurface};
use crate::units::LengthUnit;
use crate::writers::write_atomic;
use nalgebra::{Point3, Rotation3, UnitQuaternion, Vector3, Vector4};
use std::path::{Path, PathBuf};

/// A case of the cohort's `manifest.json`.
#[derive(Debug, Clone)]
pub struct CohortCase {
    pub name: String,
    /// Its surface file.
    pub surface: PathBuf,
    pub unit: LengthUnit,
    /// Its true number of vessel ends.
    pub ends: usize,
}

/// Every case of `vessels/manifest.json`, in its order (a unitless case in metres, as the
/// manifest advises).
pub fn cohort_cases(vessels: &Path) -> Result<Vec<CohortCase>, String> {
    let path = vessels.join("manifest.json");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let cases = json["cases"].as_array().ok_or("manifest.json has no list of cases")?;
    cases
        .iter()
        .map(|c| {
            let text = |key: &str| c[key].as_str().unwrap_or_default().to_string();
            let name = text("name");
            let unit = text("unit");
            let unit = if unit.starts_with("unitless") { "m".to_string() } else { unit };
            Ok(CohortCase {
                surface: vessels.join(&name).join(text("primary_surface")),
                unit: unit.parse().map_err(|e| format!("{name}: unit {unit}: {e}"))?,
                ends: c["ends"].as_u64().unwrap_or(0) as usize,
                name,
            })
        })
        .collect()
}

/// One way of writing a surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mutation {
    /// The file as published (the reference every other mutation is judged against).
    AsGiven,
    /// 30 % of the triangles wound the other way, in patches.
    FlipPatches,
    /// Every open end capped flat and untagged, with rings of triangles about as large as the
    /// wall's (thousands on a wide end) ...
    CappedFine,
    /// ... or with the fewest triangles (a fan from one rim point: slivers).
    CappedSliver,
    /// The flat caps taken off (cases that have them).
    CapsRemoved,
    /// Each triangle with its own three points.
    Unwelded,
    /// 20 % more points, which no triangle uses.
    UnreferencedPoints,
    /// Decimated to 3,000 triangles by a quadric-error edge collapse.
    Decimated,
    /// Each triangle split into four.
    Subdivided,
    /// The wall moved along its normals by up to 2 % of the local radius (smooth noise).
    NormalNoise,
    /// Every triangle wound the other way (normals into the lumen where they pointed out).
    Reversed,
    /// Rotated about its centre and written in metres (binary STL) ...
    RotatedMetres,
    /// ... or in centimetres (VTP).
    RotatedCm,
    StlAscii,
    StlBinary,
    /// VTP with polygons: pairs of triangles of a flat stretch written as one quad.
    VtpPolygons,
    /// The wall and each cap in a file of its own, caps named on the command line (`--cap`).
    SplitFiles,
    /// The same as a folder (SimVascular's `mesh-surfaces/`: wall.vtp, cap_*.vtp; `--surface DIR`).
    SplitFolder,
}

impl Mutation {
    pub const ALL: [Mutation; 18] = [
        Mutation::AsGiven,
        Mutation::FlipPatches,
        Mutation::CappedFine,
        Mutation::CappedSliver,
        Mutation::CapsRemoved,
        Mutation::Unwelded,
        Mutation::UnreferencedPoints,
        Mutation::Decimated,
        Mutation::Subdivided,
        Mutation::NormalNoise,
        Mutation::Reversed,
        Mutation::RotatedMetres,
        Mutation::RotatedCm,
        Mutation::StlAscii,
        Mutation::StlBinary,
        Mutation::VtpPolygons,
        Mutation::SplitFiles,
        Mutation::SplitFolder,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Mutation::AsGiven => "as_given",
            Mutation::FlipPatches => "flip_30pc",
            Mutation::CappedFine => "capped_fine",
            Mutation::CappedSliver => "capped_sliver",
            Mutation::CapsRemoved => "caps_removed",
            Mutation::Unwelded => "unwelded",
            Mutation::UnreferencedPoints => "unref_20pc",
            Mutation::Decimated => "decim_3k",
            Mutation::Subdivided => "subdiv_4",
            Mutation::NormalNoise => "noise_2pc",
            Mutation::Reversed => "reversed",
            Mutation::RotatedMetres => "rot_m",
            Mutation::RotatedCm => "rot_cm",
            Mutation::StlAscii => "stl_ascii",
            Mutation::StlBinary => "stl_bin",
            Mutation::VtpPolygons => "vtp_poly",
            Mutation::SplitFiles => "split_cap",
            Mutation::SplitFolder => "split_dir",
        }
    }

    pub fn from_name(name: &str) -> Option<Mutation> {
        Mutation::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// A mutation written: what to give `vesselhex mesh`, and how to read its report.
#[derive(Debug, Clone)]
pub struct Written {
    /// `--surface`: a file, or a folder of wall and caps.
    pub surface: PathBuf,
    /// `--cap NAME=FILE`, in order.
    pub caps: Vec<(String, PathBuf)>,
    pub unit: LengthUnit,
    /// The rotation and the centre it turned about (mm), when the surface was rotated: a point
    /// of the report maps back to the case's own frame by the inverse.
    pub rotation: Option<(Rotation3<f64>, Point3<f64>)>,
    /// The names the ends must have (the caps' names).
    pub end_names: Vec<String>,
}

impl Written {
    /// The arguments naming the input.
    pub fn args(&self) -> Vec<String> {
        let mut args = vec!["--surface".to_string(), self.surface.display().to_string()];
        args.extend(["--units".to_string(), self.unit.to_string()]);
        for (name, file) in &self.caps {
            args.extend(["--cap".to_string(), format!("{name}={}", file.display())]);
        }
        args
    }

    /// A point of the report (mm, the mutation's frame) in the case's frame.
    pub fn to_case_frame(&self, p: Point3<f64>) -> Point3<f64> {
        match self.rotation {
            Some((r, centre)) => centre + r.inverse() * (p - centre),
            None => p,
        }
    }
}

/// A flat cap of the case: its triangles in [`Base::surface`], and whether it is the inlet's.
#[derive(Debug, Clone)]
pub struct CapPatch {
    pub triangles: Vec<u32>,
    pub inlet: bool,
}

/// A case read once for all its mutations: its surface (millimetres, coincident points
/// welded), its flat caps, its open ends' boundary loops and the vessel's radius at each point.
pub struct Base {
    pub case: CohortCase,
    pub surface: TriangleSurface,
    pub caps: Vec<CapPatch>,
    /// Boundary loops that are vessel ends (not holes), wound as the surface's triangles next
    /// to them run their edges.
    pub open_ends: Vec<Vec<u32>>,
    /// The local vessel radius at every point: that of the nearest point of the case's own
    /// centerlines (computed from the surface as given).
    pub radius: Vec<f64>,
}

impl Base {
    pub fn new(case: &CohortCase) -> Result<Base, String> {
        let mut surface = read_surface(&case.surface, case.unit).map_err(|e| e.to_string())?;
        weld(&mut surface);
        let (clean, _) = clean_surface(surface.clone()).map_err(|e| e.to_string())?;
        let extraction = extract_centerlines(&clean, &ExtractOptions::default()).map_err(|e| e.to_string())?;
        let caps = flat_caps(&surface, &clean, &extraction);
        let open_ends = open_end_loops(&surface, &extraction);
        let radius = local_radius(&surface.vertices, &extraction);
        Ok(Base { case: case.clone(), surface, caps, open_ends, radius })
    }

    /// Whether the mutation applies to this case (a case without open ends cannot be capped,
    /// one without caps cannot lose them, a small one is not decimated).
    pub fn applies(&self, mutation: Mutation) -> bool {
        match mutation {
            Mutation::CappedFine | Mutation::CappedSliver => !self.open_ends.is_empty(),
            Mutation::CapsRemoved | Mutation::SplitFiles | Mutation::SplitFolder => !self.caps.is_empty(),
            Mutation::Decimated => self.surface.triangles.len() > 2 * DECIMATED,
            _ => true,
        }
    }

    /// Writes the mutation into `dir` (created); None when it does not apply.
    pub fn write(&self, mutation: Mutation, dir: &Path) -> Result<Option<Written>, String> {
        if !self.applies(mutation) {
            return Ok(None);
        }
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let mut rng = Rng::seeded(&format!("{}/{}", self.case.name, mutation.name()));
        let s = &self.surface;
        let tags = s.triangle_tags.clone();
        let plain = |vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>| Piece::new(vertices, triangles);
        let written = |path: PathBuf| Written {
            surface: path,
            caps: vec![],
            unit: LengthUnit::Mm,
            rotation: None,
            end_names: vec![],
        };
        let vtp = |piece: Piece, name: &str| -> Result<Written, String> {
            let path = dir.join(name);
            piece.write_vtp(&path)?;
            Ok(written(path))
        };
        let given = Piece { tags: tags.clone(), ..plain(s.vertices.clone(), s.triangles.clone()) };
        Ok(Some(match mutation {
            Mutation::AsGiven => Written { unit: self.case.unit, ..written(self.case.surface.clone()) },
            Mutation::FlipPatches => {
                let triangles = flip_patches(&s.triangles, FLIPPED_SHARE, &mut rng);
                vtp(Piece { triangles, ..given }, "flipped.vtp")?
            }
            Mutation::CappedFine | Mutation::CappedSliver => {
                let fine = mutation == Mutation::CappedFine;
                let (vertices, triangles) = self.capped(fine);
                vtp(plain(vertices, triangles), "capped.vtp")?
            }
            Mutation::CapsRemoved => vtp(self.without_caps(given), "open.vtp")?,
            Mutation::Unwelded => vtp(given.unwelded(), "unwelded.vtp")?,
            Mutation::UnreferencedPoints => vtp(given.with_stray_points(UNREFERENCED_SHARE, &mut rng), "stray.vtp")?,
            Mutation::Decimated => {
                let (vertices, triangles) = decimate(&s.vertices, &s.triangles, DECIMATED);
                vtp(plain(vertices, triangles), "decimated.vtp")?
            }
            Mutation::Subdivided => vtp(given.subdivided(), "subdivided.vtp")?,
            Mutation::NormalNoise => {
                let vertices = self.noisy(&mut rng);
                vtp(Piece { vertices, ..given }, "noisy.vtp")?
            }
            Mutation::Reversed => {
                let triangles = s.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
                vtp(Piece { triangles, ..given }, "reversed.vtp")?
            }
            Mutation::RotatedMetres | Mutation::RotatedCm => self.rotated(mutation, given, dir, &mut rng)?,
            Mutation::StlAscii => {
                let path = dir.join("surface.stl");
                given.write_stl_ascii(&path)?;
                written(path)
            }
            Mutation::StlBinary => {
                let path = dir.join("surface.stl");
                given.write_stl_binary(&path)?;
                written(path)
            }
            Mutation::VtpPolygons => vtp(given.with_quads(), "polygons.vtp")?,
            Mutation::SplitFiles | Mutation::SplitFolder => self.split(mutation == Mutation::SplitFolder, dir)?,
        }))
    }

    /// The surface with every open end closed by a flat cap: rings of triangles about as long
    /// as the rim's edges (`fine`), or a fan from one rim point.
    fn capped(&self, fine: bool) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
        let s = &self.surface;
        let (mut vertices, mut triangles) = (s.vertices.clone(), s.triangles.clone());
        for lp in &self.open_ends {
            let cap = if fine { ring_cap(&mut vertices, lp) } else { sliver_cap(lp) };
            triangles.extend(cap);
        }
        (vertices, triangles)
    }

    fn without_caps(&self, given: Piece) -> Piece {
        let mut out = vec![true; given.triangles.len()];
        self.caps.iter().flat_map(|c| &c.triangles).for_each(|&t| out[t as usize] = false);
        given.subset(&out)
    }

    /// The points moved along their normals by up to [`NOISE`] of the local radius, by a smooth
    /// field (three plane waves of random directions and phases, wavelength
    /// [`NOISE_WAVELENGTH`] median radii); the caps' points stay (a cap is cut flat).
    fn noisy(&self, rng: &mut Rng) -> Vec<Point3<f64>> {
        let s = &self.surface;
        let mut oriented = s.triangles.clone();
        orient_consistently(&mut oriented);
        let normals = crate::input::topology::vertex_normals(&s.vertices, &oriented);
        let mut on_cap = vec![false; s.vertices.len()];
        for c in &self.caps {
            c.triangles.iter().flat_map(|&t| s.triangles[t as usize]).for_each(|v| on_cap[v as usize] = true);
        }
        let mut radii = self.radius.clone();
        radii.sort_by(f64::total_cmp);
        let wavelength = NOISE_WAVELENGTH * radii[radii.len() / 2];
        let waves: Vec<(Vector3<f64>, f64)> =
            (0..3).map(|_| (rng.direction() * (std::f64::consts::TAU / wavelength), rng.uniform() * 6.3)).collect();
        let origin = s.vertices[0];
        s.vertices
            .iter()
            .enumerate()
            .map(|(v, p)| {
                if on_cap[v] {
                    return *p;
                }
                let field = waves.iter().map(|(k, phase)| (k.dot(&(p - origin)) + phase).sin()).sum::<f64>() / 3.0;
                p + normals[v] * (NOISE * self.radius[v] * field)
            })
            .collect()
    }

    /// Rotated by a random rotation about the bounding box's centre and written in metres
    /// (binary STL) or centimetres (VTP).
    fn rotated(&self, mutation: Mutation, given: Piece, dir: &Path, rng: &mut Rng) -> Result<Written, String> {
        let (lo, hi) = bounds(&given.vertices);
        let centre = Point3::from((lo.coords + hi.coords) * 0.5);
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(Vector4::new(
            rng.normal(),
            rng.normal(),
            rng.normal(),
            rng.normal(),
        )));
        let rotation = q.to_rotation_matrix();
        let unit = if mutation == Mutation::RotatedMetres { LengthUnit::M } else { LengthUnit::Cm };
        let scale = unit.from_mm();
        let vertices =
            given.vertices.iter().map(|p| Point3::from((centre + rotation * (p - centre)).coords * scale)).collect();
        let piece = Piece { vertices, ..given };
        let path = if unit == LengthUnit::M { dir.join("rotated.stl") } else { dir.join("rotated.vtp") };
        if unit == LengthUnit::M {
            piece.write_stl_binary(&path)?;
        } else {
            piece.write_vtp(&path)?;
        }
        Ok(Written { surface: path, caps: vec![], unit, rotation: Some((rotation, centre)), end_names: vec![] })
    }

    /// The wall and each cap in files of their own: binary STL named on the command line
    /// (`inlet` for the inlet's cap, `outlet_a`, `outlet_b`, ... for the others), or a folder
    /// as SimVascular writes it (wall.vtp, cap_1.vtp, ...).
    fn split(&self, folder: bool, dir: &Path) -> Result<Written, String> {
        let s = &self.surface;
        let all = Piece::new(s.vertices.clone(), s.triangles.clone());
        let mut on_cap = vec![false; s.triangles.len()];
        let mut caps = vec![];
        let mut outlets = 0u8;
        for (k, cap) in self.caps.iter().enumerate() {
            cap.triangles.iter().for_each(|&t| on_cap[t as usize] = true);
            let mut keep = vec![false; s.triangles.len()];
            cap.triangles.iter().for_each(|&t| keep[t as usize] = true);
            let name = match (folder, cap.inlet) {
                (true, _) => format!("cap_{}", k + 1),
                (false, true) => "inlet".to_string(),
                (false, false) => {
                    outlets += 1;
                    format!("outlet_{}", (b'a' + outlets - 1) as char)
                }
            };
            caps.push((name, all.subset(&keep)));
        }
        let wall = all.subset(&on_cap.iter().map(|c| !c).collect::<Vec<_>>());
        let ext = if folder { "vtp" } else { "stl" };
        let save =
            |piece: &Piece, path: &Path| if folder { piece.write_vtp(path) } else { piece.write_stl_binary(path) };
        let wall_path = dir.join(format!("wall.{ext}"));
        save(&wall, &wall_path)?;
        let mut named = vec![];
        for (name, piece) in &caps {
            let path = dir.join(format!("{name}.{ext}"));
            save(piece, &path)?;
            named.push((name.clone(), path));
        }
        let end_names = named.iter().map(|(n, _)| n.clone()).collect();
        Ok(Written {
            surface: if folder { dir.to_path_buf() } else { wall_path },
            caps: if folder { vec![] } else { named },
            unit: LengthUnit::Mm,
            rotation: None,
            end_names,
        })
    }
}

/// Writes triangles as a binary STL (single precision, as most tools write it).
pub fn write_stl(path: &Path, vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Result<(), String> {
    Piece::new(vertices.to_vec(), triangles.to_vec()).write_stl_binary(path)
}

/// Writes triangles as VTK XML polydata (ASCII, double precision).
pub fn write_vtp(path: &Path, vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Result<(), String> {
    Piece::new(vertices.to_vec(), triangles.to_vec()).write_vtp(path)
}

/// Share of the triangles wound the other way by [`Mutation::FlipPatches`].
const FLIPPED_SHARE: f64 = 0.3;
/// Share of points added, unused, by [`Mutation::UnreferencedPoints`].
const UNREFERENCED_SHARE: f64 = 0.2;
/// Triangles left by [`Mutation::Decimated`].
const DECIMATED: usize = 3000;
/// Largest move of [`Mutation::NormalNoise`], in local radii ...
const NOISE: f64 = 0.02;
/// ... and its wavelength, in median radii.
const NOISE_WAVELENGTH: f64 = 3.0;

/// The flat caps of the case found on the welded surface: the flat regions that the extraction
/// took as ends (kind cap), their triangles in `surface` (the same triangles as `clean`'s, found
/// by their points: hygiene may drop and reorder).
fn flat_caps(surface: &TriangleSurface, clean: &TriangleSurface, extraction: &Extraction) -> Vec<CapPatch> {
    let tags = clean.triangle_tags.as_ref().map(|(_, t)| t.as_slice());
    let cap_ends: Vec<(usize, Point3<f64>)> = extraction
        .ends
        .iter()
        .enumerate()
        .filter(|(_, e)| matches!(e.kind, EndKind::Cap { .. }))
        .map(|(k, e)| (k, e.centre))
        .collect();
    let key = |p: &Point3<f64>| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    let sorted_key = |s: &TriangleSurface, t: &[u32; 3]| {
        let mut k = t.map(|v| key(&s.vertices[v as usize]));
        k.sort_unstable();
        k
    };
    let index: std::collections::HashMap<_, u32> =
        surface.triangles.iter().enumerate().map(|(t, tri)| (sorted_key(surface, tri), t as u32)).collect();
    find_caps(&clean.vertices, &clean.triangles, tags)
        .into_iter()
        .filter_map(|cap| {
            let (k, _) = cap_ends.iter().find(|(_, c)| (c - cap.end.centre).norm() < 1e-9 * (1.0 + c.coords.norm()))?;
            let triangles: Option<Vec<u32>> = cap
                .triangles
                .iter()
                .map(|&t| index.get(&sorted_key(clean, &clean.triangles[t as usize])).copied())
                .collect();
            Some(CapPatch { triangles: triangles?, inlet: *k == extraction.inlet })
        })
        .collect()
}

/// The boundary loops of `surface` that the extraction took as open ends, each run the way the
/// triangles beside it run their edges (so a cap closing it winds as they do).
fn open_end_loops(surface: &TriangleSurface, extraction: &Extraction) -> Vec<Vec<u32>> {
    let mut oriented = surface.triangles.clone();
    orient_consistently(&mut oriented);
    let open: Vec<Point3<f64>> = extraction.ends.iter().filter(|e| e.kind == EndKind::Open).map(|e| e.centre).collect();
    boundary_loops(&oriented)
        .into_iter()
        .filter(|lp| {
            let (c, _) = loop_centre_and_area(&surface.vertices, lp);
            open.iter().any(|e| (e - c).norm() < 1e-9 * (1.0 + c.coords.norm()))
        })
        .map(|mut lp| {
            // The file's own triangle on the loop's first edge decides the direction.
            let (a, b) = (lp[0], lp[1]);
            let same = surface.triangles.iter().any(|t| (0..3).any(|k| t[k] == a && t[(k + 1) % 3] == b));
            if !same {
                lp.reverse();
            }
            lp
        })
        .collect()
}

/// The radius of the nearest point of the extraction's centerlines, at every point.
fn local_radius(vertices: &[Point3<f64>], extraction: &Extraction) -> Vec<f64> {
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    let samples: Vec<(Point3<f64>, f64)> = extraction
        .centerlines
        .polylines
        .iter()
        .flat_map(|l| l.points.iter().copied().zip(l.radii.iter().flatten().copied()))
        .collect();
    let points: Vec<[f64; 3]> = samples.iter().map(|(p, _)| (*p).into()).collect();
    let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(&points) else { return vec![1.0; vertices.len()] };
    vertices
        .iter()
        .map(|p| samples[tree.query(&[p.x, p.y, p.z]).nearest_one::<SquaredEuclidean<f64>>().execute().item as usize].1)
        .collect()
}

/// A cap of concentric rings from the loop's rim to its centre, spaced about as the rim's
/// points are (points added to `vertices`), wound against the loop (see `close_with_caps`).
fn ring_cap(vertices: &mut Vec<Point3<f64>>, lp: &[u32]) -> Vec<[u32; 3]> {
    let n = lp.len();
    let (centre, area) = loop_centre_and_area(vertices, lp);
    let rim: f64 = (0..n).map(|i| (vertices[lp[(i + 1) % n] as usize] - vertices[lp[i] as usize]).norm()).sum();
    let radius = (area.norm() / std::f64::consts::PI).sqrt();
    let rings = ((radius / (rim / n as f64)).round() as usize).clamp(1, 60);
    let mut outer: Vec<u32> = lp.to_vec();
    let mut triangles = vec![];
    for k in (1..rings).rev() {
        let f = k as f64 / rings as f64;
        let inner: Vec<u32> = lp
            .iter()
            .map(|&v| {
                vertices.push(centre + (vertices[v as usize] - centre) * f);
                (vertices.len() - 1) as u32
            })
            .collect();
        for i in 0..n {
            let j = (i + 1) % n;
            triangles.push([outer[j], outer[i], inner[i]]);
            triangles.push([outer[j], inner[i], inner[j]]);
        }
        outer = inner;
    }
    vertices.push(centre);
    let c = (vertices.len() - 1) as u32;
    triangles.extend((0..n).map(|i| [outer[(i + 1) % n], outer[i], c]));
    triangles
}

/// A cap of the fewest triangles: a fan from the loop's first point (long slivers).
fn sliver_cap(lp: &[u32]) -> Vec<[u32; 3]> {
    (1..lp.len() - 1).map(|i| [lp[i + 1], lp[i], lp[0]]).collect()
}

/// The triangles with `share` of them wound the other way, in patches grown over shared edges
/// from random seeds (each patch 0.5 to 3 % of the triangles).
fn flip_patches(triangles: &[[u32; 3]], share: f64, rng: &mut Rng) -> Vec<[u32; 3]> {
    let n = triangles.len();
    let neighbours = triangle_neighbours(triangles);
    let mut flipped = vec![false; n];
    let goal = (share * n as f64) as usize;
    let mut count = 0;
    while count < goal {
        let seed = rng.below(n);
        if flipped[seed] {
            continue;
        }
        let size = ((0.005 + 0.025 * rng.uniform()) * n as f64).max(1.0) as usize;
        let mut patch = std::collections::VecDeque::from([seed]);
        let mut grown = 0;
        while let Some(t) = patch.pop_front() {
            if flipped[t] {
                continue;
            }
            flipped[t] = true;
            count += 1;
            grown += 1;
            if grown >= size || count >= goal {
                break;
            }
            patch.extend(
                neighbours[t].iter().filter(|&&u| (u as usize) < n && !flipped[u as usize]).map(|&u| u as usize),
            );
        }
    }
    triangles.iter().zip(&flipped).map(|(t, &f)| if f { [t[0], t[2], t[1]] } else { *t }).collect()
}

fn bounds(points: &[Point3<f64>]) -> (Point3<f64>, Point3<f64>) {
    points.iter().fold((Point3::from([f64::MAX; 3]), Point3::from([f64::MIN; 3])), |(lo, hi), p| (lo.inf(p), hi.sup(p)))
}

/// Polygons (triangles, or quads of [`Piece::with_quads`]) over points, with an optional
/// integer tag per polygon: what one file holds.
#[derive(Debug, Clone)]
struct Piece {
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    /// Polygons of more than three points replacing the triangles, when set.
    polygons: Option<Vec<Vec<u32>>>,
    tags: Option<(String, Vec<i64>)>,
}

impl Piece {
    fn new(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>) -> Piece {
        Piece { vertices, triangles, polygons: None, tags: None }
    }

    fn polygons(&self) -> Vec<Vec<u32>> {
        self.polygons.clone().unwrap_or_else(|| self.triangles.iter().map(|t| t.to_vec()).collect())
    }

    /// The triangles `keep` says, and only the points they use.
    fn subset(&self, keep: &[bool]) -> Piece {
        let mut index = vec![u32::MAX; self.vertices.len()];
        let mut vertices = vec![];
        let mut triangles = vec![];
        for (t, _) in self.triangles.iter().zip(keep).filter(|(_, k)| **k) {
            triangles.push(t.map(|v| {
                if index[v as usize] == u32::MAX {
                    index[v as usize] = vertices.len() as u32;
                    vertices.push(self.vertices[v as usize]);
                }
                index[v as usize]
            }));
        }
        let tags = self
            .tags
            .as_ref()
            .map(|(name, t)| (name.clone(), t.iter().zip(keep).filter(|(_, k)| **k).map(|(v, _)| *v).collect()));
        Piece { vertices, triangles, polygons: None, tags }
    }

    fn unwelded(self) -> Piece {
        let vertices = self.triangles.iter().flat_map(|t| t.map(|v| self.vertices[v as usize])).collect();
        let triangles = (0..self.triangles.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
        Piece { vertices, triangles, ..self }
    }

    /// `share` more points, scattered over the bounding box, which no triangle uses (every
    /// fifth one in the middle of the list, the rest at its end).
    fn with_stray_points(mut self, share: f64, rng: &mut Rng) -> Piece {
        let (lo, hi) = bounds(&self.vertices);
        let extra = (share * self.vertices.len() as f64).ceil() as usize;
        let stray: Vec<Point3<f64>> = (0..extra)
            .map(|_| Point3::new(rng.between(lo.x, hi.x), rng.between(lo.y, hi.y), rng.between(lo.z, hi.z)))
            .collect();
        let middle = self.vertices.len() / 2;
        let (first, rest) = stray.split_at(extra / 5);
        // Points inserted in the middle shift the later indices.
        let shift = first.len() as u32;
        self.triangles.iter_mut().flatten().filter(|v| **v as usize >= middle).for_each(|v| *v += shift);
        self.vertices.splice(middle..middle, first.iter().copied());
        self.vertices.extend_from_slice(rest);
        self
    }

    /// Each triangle split into four at its edges' middles (shared by neighbours).
    fn subdivided(self) -> Piece {
        let mut vertices = self.vertices.clone();
        let mut middle = std::collections::HashMap::new();
        let mut at = |a: u32, b: u32, vertices: &mut Vec<Point3<f64>>| -> u32 {
            *middle.entry((a.min(b), a.max(b))).or_insert_with(|| {
                vertices.push(Point3::from((vertices[a as usize].coords + vertices[b as usize].coords) * 0.5));
                (vertices.len() - 1) as u32
            })
        };
        let mut triangles = vec![];
        for &[a, b, c] in &self.triangles {
            let (ab, bc, ca) = (at(a, b, &mut vertices), at(b, c, &mut vertices), at(c, a, &mut vertices));
            triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        let tags = self.tags.map(|(name, t)| (name, t.iter().flat_map(|&v| [v; 4]).collect()));
        Piece { vertices, triangles, polygons: None, tags }
    }

    /// Pairs of neighbouring triangles within 1 degree of one plane (and of the same tag)
    /// written as one quad, starting at a corner of their shared edge, so that a fan from its
    /// first point gives the two triangles back.
    fn with_quads(self) -> Piece {
        let neighbours = triangle_neighbours(&self.triangles);
        let normal = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|v| self.vertices[v as usize]);
            (b - a).cross(&(c - a)).try_normalize(0.0)
        };
        let tag = |t: usize| self.tags.as_ref().map(|(_, v)| v[t]);
        let mut used = vec![false; self.triangles.len()];
        let (mut polygons, mut tags) = (vec![], vec![]);
        for t in 0..self.triangles.len() {
            if used[t] {
                continue;
            }
            used[t] = true;
            let tri = self.triangles[t];
            let pair = (0..3).find_map(|k| {
                let u = neighbours[t][k] as usize;
                let flat = normal(&tri).zip(normal(self.triangles.get(u)?)).is_some_and(|(a, b)| a.dot(&b) > 0.99985);
                (!used[u] && flat && tag(t) == tag(u)).then_some((k, u))
            });
            match pair {
                Some((k, u)) => {
                    used[u] = true;
                    // Edge k runs tri[k] -> tri[k+1]; the other triangle's far corner closes the quad.
                    let (a, b, c) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
                    let far = self.triangles[u].into_iter().find(|v| *v != a && *v != b).expect("a neighbour");
                    polygons.push(vec![b, c, a, far]);
                }
                None => polygons.push(tri.to_vec()),
            }
            tags.extend(tag(t));
        }
        let tags = self.tags.map(|(name, _)| (name, tags));
        Piece { polygons: Some(polygons), tags, ..self }
    }

    /// VTK XML polydata, ASCII, points as Float64 with 17 significant digits.
    fn write_vtp(&self, path: &Path) -> Result<(), String> {
        let polygons = self.polygons();
        write_atomic(path, |w| {
            writeln!(w, r#"<?xml version="1.0"?>"#)?;
            writeln!(w, r#"<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">"#)?;
            writeln!(w, "  <PolyData>")?;
            writeln!(w, r#"    <Piece NumberOfPoints="{}" NumberOfPolys="{}">"#, self.vertices.len(), polygons.len())?;
            writeln!(w, r#"      <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">"#)?;
            for p in &self.vertices {
                writeln!(w, "{:.17e} {:.17e} {:.17e}", p.x, p.y, p.z)?;
            }
            writeln!(w, "      </DataArray></Points>")?;
            if let Some((name, tags)) = &self.tags {
                writeln!(w, r#"      <CellData><DataArray type="Int32" Name="{name}" format="ascii">"#)?;
                for t in tags {
                    writeln!(w, "{t}")?;
                }
                writeln!(w, "      </DataArray></CellData>")?;
            }
            writeln!(w, r#"      <Polys><DataArray type="Int64" Name="connectivity" format="ascii">"#)?;
            for poly in &polygons {
                let line: Vec<String> = poly.iter().map(|v| v.to_string()).collect();
                writeln!(w, "{}", line.join(" "))?;
            }
            writeln!(w, r#"      </DataArray><DataArray type="Int64" Name="offsets" format="ascii">"#)?;
            let mut end = 0;
            for poly in &polygons {
                end += poly.len();
                writeln!(w, "{end}")?;
            }
            writeln!(w, "      </DataArray></Polys>\n    </Piece>\n  </PolyData>\n</VTKFile>")
        })
        .map_err(|e| e.to_string())
    }

    /// ASCII STL as most tools write it: single-precision values in exponent notation.
    fn write_stl_ascii(&self, path: &Path) -> Result<(), String> {
        write_atomic(path, |w| {
            writeln!(w, "solid vessel")?;
            for t in &self.triangles {
                let [a, b, c] = t.map(|v| self.vertices[v as usize]);
                let n = (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or_default();
                writeln!(w, "  facet normal {:e} {:e} {:e}\n    outer loop", n.x as f32, n.y as f32, n.z as f32)?;
                for p in [a, b, c] {
                    writeln!(w, "      vertex {:e} {:e} {:e}", p.x as f32, p.y as f32, p.z as f32)?;
                }
                writeln!(w, "    endloop\n  endfacet")?;
            }
            writeln!(w, "endsolid vessel")
        })
        .map_err(|e| e.to_string())
    }

    fn write_stl_binary(&self, path: &Path) -> Result<(), String> {
        crate::synthetic::write_binary_stl(path, "vesselhex mutation suite", &self.vertices, &self.triangles)
            .map_err(|e| e.to_string())
    }
}

/// SplitMix64 (Steele, Lea & Flood 2014): small, seeded, enough for scattering test input.
pub struct Rng(u64);

impl Rng {
    /// Seeded by a text (FNV-1a of its bytes).
    pub fn seeded(text: &str) -> Rng {
        Rng(text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn between(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.uniform() * n as f64) as usize % n.max(1)
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let (u, v) = (1.0 - self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// A random unit vector.
    pub fn direction(&mut self) -> Vector3<f64> {
        loop {
            if let Some(d) = Vector3::new(self.normal(), self.normal(), self.normal()).try_normalize(1e-9) {
                return d;
            }
        }
    }
}
