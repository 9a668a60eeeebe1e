//! How a run writes its formats: independent jobs on two threads, the formats derived from the
//! lumen polyMesh sharing one build of it.
//!
//! Each job writes its own files, so the bytes do not depend on the order in which the jobs run
//! or on the thread count; the paths come back in the order of the formats asked. Two threads
//! because the writers' long lists already format on every core ([`super::text::write_items`]):
//! a second job fills what the first leaves idle (its serial writes, its syncs to disk, the
//! polyMesh pairing), and only the lumen job holds memory of the mesh's size, so two jobs at
//! once add the other job's buffers to its peak (15 MiB at most, `febio`'s, at 0.8 M hexes),
//! not a second polyMesh.

use super::{fsi, openfoam, WriteOptions};
use crate::data::error::Result;
use crate::geometry::mesh::VesselMesh;
use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

/// The formats whose files derive from the lumen polyMesh.
const LUMEN_FORMATS: [&str; 3] = ["openfoam", "fsi", "openfoam-fsi"];

/// Jobs running at once.
const THREADS: usize = 2;

/// A job: the formats (indices into the run's list) it writes.
enum Job {
    One(usize),
    /// Formats of [`LUMEN_FORMATS`] getting the same mesh, written from one build of the lumen
    /// polyMesh ([`write_lumen_formats`]).
    Lumen(Vec<usize>),
}

/// The files of each format a job wrote, by index into the run's list.
type Written = Vec<(usize, Vec<PathBuf>)>;

/// Writes `formats` under `dir`, each from the mesh `mesh_for` gives it, and returns the paths
/// written in the order of `formats`. On a failure no new job starts; the error returned is that
/// of the failed job whose first format comes first in `formats`.
pub fn write_formats<'m>(
    formats: &[&str],
    mesh_for: &(dyn Fn(&str) -> Cow<'m, VesselMesh> + Sync),
    options: &WriteOptions,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    let jobs = plan(formats, mesh_for);
    // One thread when rayon is told to use one (RAYON_NUM_THREADS=1): the run stays serial.
    let threads = THREADS.min(rayon::current_num_threads()).min(jobs.len()).max(1);
    let (next, failed) = (AtomicUsize::new(0), AtomicBool::new(false));
    let results: Mutex<Vec<(usize, Result<Written>)>> = Mutex::new(Vec::new());
    let work = || {
        while !failed.load(Ordering::Relaxed) {
            let Some(job) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) else { return };
            let result = run(job, formats, mesh_for, options, dir);
            failed.fetch_or(result.is_err(), Ordering::Relaxed);
            results.lock().expect("no writer panicked").push((first_format(job), result));
        }
    };
    std::thread::scope(|s| {
        (1..threads).for_each(|_| {
            s.spawn(work);
        });
        work();
    });
    let mut results = results.into_inner().expect("no writer panicked");
    results.sort_by_key(|r| r.0);
    let mut written = Vec::new();
    for (_, result) in results {
        written.extend(result?);
    }
    written.sort_by_key(|w| w.0);
    Ok(written.into_iter().flat_map(|w| w.1).collect())
}

/// The jobs: the lumen formats that get one mesh together (the longest job, first), then every
/// other format alone in the order asked.
fn plan<'m>(formats: &[&str], mesh_for: &(dyn Fn(&str) -> Cow<'m, VesselMesh> + Sync)) -> Vec<Job> {
    let index = |f: &str| formats.iter().position(|x| *x == f);
    let lumen: Vec<usize> = LUMEN_FORMATS.iter().filter_map(|f| index(f)).collect();
    let shared: Vec<usize> = match lumen.first() {
        Some(&first) => {
            // The same mesh: borrowed from one (a copy made for a format is another object).
            let mesh = mesh_for(formats[first]);
            lumen.iter().copied().filter(|&i| std::ptr::eq::<VesselMesh>(&*mesh, &*mesh_for(formats[i]))).collect()
        }
        None => Vec::new(),
    };
    let shared = if shared.len() > 1 { shared } else { Vec::new() };
    let mut jobs = Vec::new();
    if !shared.is_empty() {
        jobs.push(Job::Lumen(shared.clone()));
    }
    jobs.extend((0..formats.len()).filter(|i| !shared.contains(i)).map(Job::One));
    jobs
}

fn first_format(job: &Job) -> usize {
    match job {
        Job::One(i) => *i,
        Job::Lumen(formats) => formats.iter().copied().min().unwrap_or(0),
    }
}

fn run<'m>(
    job: &Job,
    formats: &[&str],
    mesh_for: &(dyn Fn(&str) -> Cow<'m, VesselMesh> + Sync),
    options: &WriteOptions,
    dir: &Path,
) -> Result<Written> {
    match job {
        Job::One(i) => {
            let write = super::writer(formats[*i]).expect("a format of the table");
            Ok(vec![(*i, write(&mesh_for(formats[*i]), options, dir)?)])
        }
        Job::Lumen(members) => write_lumen_formats(&mesh_for(formats[members[0]]), members, formats, options, dir),
    }
}

/// Writes the lumen formats `members` from one build of the lumen polyMesh. The polyMesh of
/// `openfoam-fsi` goes first, built, written and dropped before the lumen's is built (the two are
/// never held together): its build, the least parallel part of the run, overlaps the other
/// thread's jobs, and the lists left for the end format on every core. Its system files, whose
/// values come from the lumen's polyMesh, follow.
fn write_lumen_formats(
    mesh: &VesselMesh,
    members: &[usize],
    formats: &[&str],
    options: &WriteOptions,
    dir: &Path,
) -> Result<Written> {
    let fsi_mesh = members.iter().find(|&&i| formats[i] == "openfoam-fsi");
    let mut fsi_mesh_files = match fsi_mesh {
        Some(_) => openfoam::write_openfoam_fsi_mesh(mesh, options, dir)?,
        None => Vec::new(),
    };
    let lumen = openfoam::lumen_polymesh(mesh)?;
    let mut written = Vec::new();
    for &i in members {
        let files = match formats[i] {
            "openfoam" => openfoam::write_openfoam_of(mesh, &lumen, options, dir)?,
            "fsi" => fsi::write_fsi_of(mesh, &lumen, options, dir)?,
            "openfoam-fsi" => {
                let values = openfoam::FsiSystemValues::of(mesh, &lumen, options)?;
                fsi_mesh_files.extend(openfoam::write_openfoam_fsi_system(mesh, &values, dir)?);
                std::mem::take(&mut fsi_mesh_files)
            }
            other => unreachable!("{other} is not a lumen format"),
        };
        written.push((i, files));
    }
    Ok(written)
}
