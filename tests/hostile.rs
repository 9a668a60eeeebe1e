//! Hostile and careless input, as a new user or a script brings it: every refusal is one line
//! `vesselhex: error: ...` with the documented exit code, no panic, peak memory under 1 GiB,
//! and nothing left in or beside the output folder; interruption by real signals leaves nothing
//! either; outputs are committed whole, only into folders vesselhex owns.
#![cfg(unix)]

mod common;

use common::{crate_dir, fixture, path_str, temp_dir};
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Exit codes (docs/guide/command-line.md): 1 error, 2 usage error, 128 + signal when interrupted.
const ERROR: i32 = 1;
const USAGE: i32 = 2;

/// Peak memory a refused run may take.
const REFUSED_PEAK_KIB: i64 = 1 << 20;

/// How a finished `vesselhex` child ended.
struct Outcome {
    code: i32,
    stderr: String,
    /// Its peak resident memory (wait4's rusage).
    max_rss_kib: i64,
}

/// A running `vesselhex` child whose end is collected with wait4 (for its own peak memory).
struct Child {
    pid: i32,
    stderr: std::thread::JoinHandle<String>,
    _child: std::process::Child,
}

fn spawn(args: &[&str], cwd: &Path) -> Child {
    let mut child = Command::new(env!("CARGO_BIN_EXE_vesselhex"))
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run vesselhex");
    let mut pipe = child.stderr.take().unwrap();
    let stderr = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = pipe.read_to_string(&mut s);
        s
    });
    Child { pid: child.id() as i32, stderr, _child: child }
}

impl Child {
    /// Waits at most a minute (a run that blocks, on a named pipe say, fails the test).
    fn finish(self) -> Outcome {
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut status = 0;
        // SAFETY: plain libc calls on our own child's pid with valid out-pointers.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        loop {
            let r = unsafe { libc::wait4(self.pid, &mut status, libc::WNOHANG, &mut usage) };
            if r == self.pid {
                break;
            }
            assert!(r == 0, "wait4 failed");
            if Instant::now() > deadline {
                unsafe { libc::kill(self.pid, libc::SIGKILL) };
                panic!("vesselhex did not finish within a minute (blocked?)");
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        let code = if libc::WIFEXITED(status) { libc::WEXITSTATUS(status) } else { 128 + libc::WTERMSIG(status) };
        Outcome { code, stderr: self.stderr.join().unwrap(), max_rss_kib: usage.ru_maxrss }
    }

    fn signal(&self, signal: i32) {
        // SAFETY: sends a signal to our own child.
        assert_eq!(unsafe { libc::kill(self.pid, signal) }, 0, "kill");
    }
}

fn run_in(cwd: &Path, args: &[&str]) -> Outcome {
    spawn(args, cwd).finish()
}

/// Every entry under `dir` (links not followed) with its kind and, for files, content.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap().flatten() {
            let path = entry.path();
            let meta = std::fs::symlink_metadata(&path).unwrap();
            let rel = path.strip_prefix(dir).unwrap().to_path_buf();
            if meta.is_dir() {
                stack.push(path);
                out.insert(rel, b"<dir>".to_vec());
            } else if meta.file_type().is_symlink() {
                out.insert(rel, format!("<link {}>", std::fs::read_link(&path).unwrap().display()).into_bytes());
            } else if meta.is_file() && meta.len() < (64 << 20) {
                out.insert(rel, std::fs::read(&path).unwrap());
            } else {
                out.insert(rel, format!("<{} bytes>", meta.len()).into_bytes());
            }
        }
    }
    out
}

/// A case folder: inputs under `in/`, the output at `out`, all of it watched.
struct Case {
    base: PathBuf,
}

impl Case {
    fn new(tag: &str) -> Case {
        let base = temp_dir(&format!("hostile-{tag}"));
        std::fs::create_dir_all(base.join("in")).unwrap();
        Case { base }
    }

    fn input(&self, name: &str) -> PathBuf {
        self.base.join("in").join(name)
    }

    fn write(&self, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
        let p = self.input(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn out(&self) -> PathBuf {
        self.base.join("out")
    }

    /// `vesselhex mesh --quiet` run in the case folder, with `--output out` and the AAA fixture's
    /// surface and centerline unless `args` give their own.
    fn mesh(&self, args: &[&str]) -> Outcome {
        let (stl, csv) = fixture("aaa");
        let mut all = vec!["mesh", "--quiet"];
        for (flag, default) in [("--output", "out"), ("--surface", path_str(&stl)), ("--centerlines", path_str(&csv))] {
            if !args.contains(&flag) {
                all.extend([flag, default]);
            }
        }
        all.extend_from_slice(args);
        run_in(&self.base, &all)
    }

    /// Runs `args` (as [`Case::mesh`]) and checks the refusal contract: exit `code`, one line
    /// `vesselhex: error: ...` naming `what`, no panic, peak memory under 1 GiB, the case folder
    /// exactly as before. Returns the message.
    fn refused(&self, args: &[&str], code: i32, what: &str) -> String {
        let before = snapshot(&self.base);
        let o = self.mesh(args);
        assert_refusal(&o, code, what, args);
        let after = snapshot(&self.base);
        assert!(before == after, "{args:?}: the case folder changed: {:?}", diff(&before, &after));
        o.stderr
    }
}

fn assert_refusal(o: &Outcome, code: i32, what: &str, args: &[&str]) {
    let err = &o.stderr;
    assert!(!err.contains("panicked"), "{args:?}: panic: {err}");
    assert_eq!(o.code, code, "{args:?}: exit code: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: one line: {err}");
    assert!(err.starts_with("vesselhex: error: "), "{args:?}: {err}");
    assert!(err.contains(what), "{args:?}: the error should say '{what}': {err}");
    assert!(o.max_rss_kib < REFUSED_PEAK_KIB, "{args:?}: peak memory {} MiB", o.max_rss_kib / 1024);
}

fn diff(a: &BTreeMap<PathBuf, Vec<u8>>, b: &BTreeMap<PathBuf, Vec<u8>>) -> Vec<PathBuf> {
    let keys: std::collections::BTreeSet<&PathBuf> = a.keys().chain(b.keys()).collect();
    keys.into_iter().filter(|k| a.get(*k) != b.get(*k)).cloned().collect()
}

/// The fixture's centerline with each data row passed through `edit(row index, [x, y, z, r])`.
fn edited_centerline(edit: impl Fn(usize, &mut [f64; 4])) -> String {
    let (_, csv) = fixture("aaa");
    let text = std::fs::read_to_string(csv).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            out.push_str(line);
        } else {
            let mut v = [0.0; 4];
            for (k, x) in line.split(',').enumerate() {
                v[k] = x.parse().unwrap();
            }
            edit(i - 1, &mut v);
            out.push_str(&format!("{:e},{:e},{:e},{:e}", v[0], v[1], v[2], v[3]));
        }
        out.push('\n');
    }
    out
}

/// A VTP surface whose one compressed array has `blocks` zlib blocks each inflating to
/// `block` bytes (the same few hundred kB of zlib data, repeated): a decompression bomb.
fn zlib_bomb(blocks: u32, block: u32) -> Vec<u8> {
    use std::io::Write;
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&vec![0u8; block as usize]).unwrap();
    let z = z.finish().unwrap();
    let points = blocks as u64 * block as u64 / 12;
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" \
         header_type=\"UInt32\" compressor=\"vtkZLibDataCompressor\">\n<PolyData><Piece NumberOfPoints=\"{points}\" \
         NumberOfPolys=\"0\">\n<Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" \
         offset=\"0\"/></Points>\n</Piece></PolyData>\n<AppendedData encoding=\"raw\">_"
    )
    .into_bytes();
    for word in [blocks, block, block].into_iter().chain((0..blocks).map(|_| z.len() as u32)) {
        out.extend_from_slice(&word.to_le_bytes());
    }
    for _ in 0..blocks {
        out.extend_from_slice(&z);
    }
    out.extend_from_slice(b"\n</AppendedData></VTKFile>\n");
    out
}

#[test]
fn what_would_exhaust_the_machine_is_refused_before_it_is_allocated() {
    let c = Case::new("resources");
    let tiny_radius = c.write("tiny_radius.csv", edited_centerline(|_, v| v[3] = 1e-9));
    c.refused(&["--centerlines", path_str(&tiny_radius)], ERROR, "the mesh would need about");
    let mistyped = c.write("mistyped.csv", edited_centerline(|i, v| v[2] = if i == 56 { 1e9 } else { v[2] }));
    c.refused(&["--centerlines", path_str(&mistyped)], ERROR, "point 56");
    let huge = c.write("huge.csv", edited_centerline(|i, v| v[0] = if i == 56 { 1e308 } else { v[0] }));
    c.refused(&["--centerlines", path_str(&huge)], ERROR, "beyond 1e7 mm");
    let spacing = c.write("spacing.toml", "[lumen]\naxial_spacing_mm = 1e-7\n");
    c.refused(&["--config", path_str(&spacing)], ERROR, "lumen.axial_spacing_mm");
    // Within every accepted range, and about 460 GiB.
    let layer =
        |name: &str, angle: f64| format!("[wall.{name}]\nfraction = 0.33\nelements = 50\nfibre_angle_deg = {angle}\n");
    let big = c.write(
        "big.toml",
        format!(
            "[lumen]\ncore_elements = 200\nradial_elements = 200\naxial_spacing = 0.0101\n{}{}{}",
            layer("intima", 29.0),
            layer("media", 29.0),
            layer("adventitia", 62.0)
        ),
    );
    let e = c.refused(&["--config", path_str(&big)], ERROR, "the mesh would need about");
    assert!(e.contains("--max-memory"), "{e}");
    let smoothing = c.write("smoothing.toml", "[centerline]\nsmoothing_passes = 4000000000\n");
    c.refused(&["--config", path_str(&smoothing)], ERROR, "centerline.smoothing_passes");
    for threads in ["10000", "1000000"] {
        c.refused(&["--threads", threads], USAGE, "--threads");
    }
    // Sixty blocks of 200 MB each: 12 GB announced, refused before one block is inflated.
    let bomb = c.write("bomb.vtp", zlib_bomb(60, 200_000_000));
    c.refused(&["--surface", path_str(&bomb)], ERROR, "decompression bomb");
    // A file larger than a tenth of --max-memory (sparse: it takes no disk).
    let large = c.input("large.stl");
    std::fs::File::create(&large).unwrap().set_len(300 << 20).unwrap();
    c.refused(&["--surface", path_str(&large), "--max-memory", "1G"], ERROR, "raise --max-memory");
}

#[test]
fn only_regular_files_are_read() {
    let c = Case::new("special-files");
    let fifo = c.input("pipe.stl");
    let name = std::ffi::CString::new(path_str(&fifo)).unwrap();
    // SAFETY: creates a named pipe at a path we own.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o644) }, 0);
    c.refused(&["--surface", path_str(&fifo)], ERROR, "named pipe");
    let zero = c.input("zero.stl");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    c.refused(&["--surface", path_str(&zero)], ERROR, "a device");
    let folder = c.input("folder.stl");
    std::fs::create_dir(&folder).unwrap();
    c.refused(&["--surface", path_str(&folder)], ERROR, "a folder");
    let case = c.input("case.toml");
    std::os::unix::fs::symlink("/dev/zero", &case).unwrap();
    c.refused(&["--config", path_str(&case)], ERROR, "a device");
}

#[test]
fn settings_out_of_bounds_are_named_with_their_line() {
    let c = Case::new("settings");
    let cases = [
        ("[wall]\nthickness_mm = 1e9\n", "line 2: wall.thickness_mm"),
        ("[febio]\nstatic_steps = 4000000000\n", "line 2: febio.static_steps"),
        ("[lumen]\nradial_elementz = 9\n", "line 2: unknown field `radial_elementz`"),
        ("[lumen\nradial_elements = 9\n", "line 1, column 7: not valid TOML"),
        ("\n[lumen]\ncore_elements = \"four\"\n", "line 3: invalid type"),
        ("[wall.intima]\nfraction = 1e-9\nelements = 1\nfibre_angle_deg = 29.0\n", "at least 1 % of the wall"),
    ];
    for (k, (text, what)) in cases.iter().enumerate() {
        let case = c.write(&format!("case{k}.toml"), text);
        c.refused(&["--config", path_str(&case)], ERROR, what);
    }
    // A relative thickness that fits the settings' bounds but not this vessel (radius 10 mm).
    let thick = c.write("thick.toml", "[wall]\nthickness_mm = 50.0\n");
    c.refused(&["--config", path_str(&thick)], ERROR, "times the vessel's median radius");
    // clap's own usage errors, on one line with the usage.
    let e = c.refused(&["--surfac", "x"], USAGE, "unexpected argument '--surfac'");
    assert!(e.contains("Usage: vesselhex mesh"), "{e}");
    c.refused(&["--max-memory", "lots"], USAGE, "is not a size");
}

#[test]
fn templates_come_from_their_own_folder_beside_the_case_file() {
    let c = Case::new("templates");
    let dir = c.input("my-templates");
    std::fs::create_dir_all(dir.join("calculix")).unwrap();
    let builtin = std::fs::read_to_string(crate_dir().join("templates/calculix/material_hgo.inp")).unwrap();
    std::fs::write(dir.join("calculix/material_hgo.inp"), format!("** my own material\n{builtin}")).unwrap();
    // The case-file guide's own line, resolved against the case file's folder (the run's is elsewhere).
    let case = c.write("case.toml", "[fe]\ntemplate_dir = \"my-templates\"\n");
    let o = c.mesh(&["--config", path_str(&case), "--formats", "calculix"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let deck = std::fs::read_to_string(c.out().join("calculix/model.inp")).unwrap();
    assert!(deck.contains("** my own material"), "the user's template was not used");
    std::fs::remove_dir_all(c.out()).unwrap();

    for (k, (dir, what)) in [
        ("missing", "does not exist"),
        ("case.toml", "is not a folder"),
        ("../../../../../../../../etc", "leads out of the case file's folder"),
        ("/", "holds neither an abaqus/ nor a calculix/ folder"),
    ]
    .iter()
    .enumerate()
    {
        let case = c.write(&format!("bad{k}.toml"), format!("[fe]\ntemplate_dir = \"{dir}\"\n"));
        c.refused(&["--config", path_str(&case), "--formats", "calculix"], ERROR, what);
    }
    // A template that is a link to a file outside the folder is refused, not copied in a deck.
    let secret = c.write("secret.txt", "not for a deck\n");
    std::os::unix::fs::symlink(&secret, dir.join("calculix/step_inflation.inp")).unwrap();
    c.refused(&["--config", path_str(&case), "--formats", "calculix"], ERROR, "leading out of the template folder");
}

#[test]
fn messages_name_the_real_cause() {
    let c = Case::new("causes");
    let dir = crate_dir().join("fixtures");
    let (y_stl, y_cl) = (dir.join("y_bifurcation.stl"), dir.join("y_bifurcation_centerlines.vtp"));
    // A branched vessel whose centerline is in other units: units, not the junction's shape.
    let e = c.refused(
        &["--surface", path_str(&y_stl), "--centerlines", path_str(&y_cl), "--centerline-units", "cm"],
        ERROR,
        "different units",
    );
    assert!(e.contains("times the surface's extent") && !e.contains("the junction"), "{e}");
    // Another vessel's centerlines.
    let t_cl = dir.join("t_junction_centerlines.vtp");
    let e = c.refused(&["--surface", path_str(&y_stl), "--centerlines", path_str(&t_cl)], ERROR, "outside the lumen");
    assert!(!e.contains("the junction"), "{e}");
    // Triangles wound inconsistently, every tenth one turned over: no refusal since issue 45, the
    // winding is repaired and said (a surface that cannot be wound one way is refused, see
    // tests/mutations.rs).
    let (stl, _) = fixture("aaa");
    let mut bytes = std::fs::read(&stl).unwrap();
    let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    for t in (0..n).step_by(10) {
        let at = 84 + 50 * t + 24;
        let (a, b) = bytes[at..at + 24].split_at(12);
        let swapped = [b, a].concat();
        bytes[at..at + 24].copy_from_slice(&swapped);
    }
    let flipped = c.write("flipped.stl", bytes);
    let o = c.mesh(&["--surface", path_str(&flipped)]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    let said = format!("{} triangles wound against their neighbours flipped", n.div_ceil(10));
    assert!(o.stderr.contains(&said), "{}", o.stderr);
    let _ = std::fs::remove_dir_all(c.out());
    // A closed loop.
    let ring: String = std::iter::once("x,y,z,r\n".to_string())
        .chain((0..200).map(|i| {
            let t = std::f64::consts::TAU * i as f64 / 200.0;
            format!("{},{},0,3\n", 30.0 * t.cos(), 30.0 * t.sin())
        }))
        .collect();
    let ring = c.write("ring.csv", ring);
    c.refused(&["--centerlines", path_str(&ring)], ERROR, "closed loop");
    // UTF-16 text.
    let csv = std::fs::read_to_string(fixture("aaa").1).unwrap();
    let utf16: Vec<u8> = [0xFF, 0xFE].into_iter().chain(csv.encode_utf16().flat_map(u16::to_le_bytes)).collect();
    let utf16 = c.write("utf16.csv", utf16);
    c.refused(&["--centerlines", path_str(&utf16)], ERROR, "UTF-16");
}

/// A run that succeeds with `what` among its warnings, on stderr and in report.json.
fn assert_warned(o: &Outcome, out: &Path, kind: &str, what: &str) {
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(
        o.stderr.lines().any(|l| l.starts_with("vesselhex: warning: ") && l.contains(what)),
        "no warning '{what}': {}",
        o.stderr
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let warnings = report["warnings"].as_array().unwrap();
    assert!(
        warnings.iter().any(|w| w["kind"] == kind && w["message"].as_str().unwrap().contains(what)),
        "report.json lacks the {kind} warning '{what}': {warnings:?}"
    );
}

#[test]
fn plausibility_warnings_reach_stderr_and_the_report() {
    let c = Case::new("warnings");
    // A surface and centerline in metres read as mm: a vessel of 10 um.
    let (stl, _) = fixture("aaa");
    let mut bytes = std::fs::read(&stl).unwrap();
    let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    for t in 0..n {
        for k in 0..12 {
            let at = 84 + 50 * t + 4 * k;
            let x = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) / 1000.0;
            bytes[at..at + 4].copy_from_slice(&x.to_le_bytes());
        }
    }
    let metres = c.write("metres.stl", bytes);
    let metres_cl = c.write("metres.csv", edited_centerline(|_, v| v.iter_mut().for_each(|x| *x /= 1000.0)));
    let o = c.mesh(&["--surface", path_str(&metres), "--centerlines", path_str(&metres_cl)]);
    assert_warned(&o, &c.out(), "units", "give --units m");
    // The AAA in mm read as metres: a 10 m aorta.
    let o = c.mesh(&["--units", "m"]);
    assert_warned(&o, &c.out(), "units", "give --units mm");
    // Layer fractions that do not sum to 1, and --threads 0.
    let layer = |name: &str| format!("[wall.{name}]\nfraction = 0.5\nelements = 1\nfibre_angle_deg = 29.0\n");
    let case = c.write("fractions.toml", format!("{}{}{}", layer("intima"), layer("media"), layer("adventitia")));
    let o = c.mesh(&["--config", path_str(&case), "--threads", "0"]);
    assert_warned(&o, &c.out(), "settings", "normalised to 0.333/0.333/0.333");
    assert_warned(&o, &c.out(), "settings", "--threads 0 means all cores");
    // A byte-order mark before the CSV header is no error.
    let bom = c.write("bom.csv", [b"\xEF\xBB\xBF".as_slice(), &std::fs::read(fixture("aaa").1).unwrap()].concat());
    let o = c.mesh(&["--centerlines", path_str(&bom)]);
    assert_eq!(o.code, 0, "{}", o.stderr);
}

fn report_outputs(out: &Path) -> Vec<String> {
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let mut listed: Vec<String> =
        report["outputs"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().into()).collect();
    listed.sort();
    listed
}

fn files_in(out: &Path) -> Vec<String> {
    let mut files: Vec<String> =
        snapshot(out).into_iter().filter(|(_, v)| v != b"<dir>").map(|(k, _)| k.display().to_string()).collect();
    files.sort();
    files
}

#[test]
fn outputs_are_replaced_whole_and_only_where_vesselhex_wrote() {
    let c = Case::new("ownership");
    let out = c.out();
    let o = c.mesh(&["--formats", "vtu,calculix,openfoam"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(files_in(&out), report_outputs(&out), "report.json lists every file written");
    // A rerun with fewer formats leaves no stale format behind.
    let o = c.mesh(&["--formats", "vtu"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(files_in(&out), ["mesh.vtu", "report.json"]);
    // A user's file inside vesselhex's folder: the folder is not replaced without --force.
    let o = c.mesh(&["--formats", "vtu,openfoam"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    std::fs::create_dir_all(out.join("openfoam/my_case")).unwrap();
    std::fs::write(out.join("openfoam/my_case/IMPORTANT.txt"), "results").unwrap();
    c.refused(&["--formats", "vtu"], ERROR, "openfoam/my_case in the output folder was not written by vesselhex");
    let o = c.mesh(&["--formats", "vtu", "--force"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(files_in(&out), ["mesh.vtu", "report.json"]);
    // A file in the way of a format, and a failing run: the old result stays as it was.
    std::fs::write(out.join("openfoam"), "in the way").unwrap();
    c.refused(&["--formats", "vtu,calculix,openfoam"], ERROR, "openfoam in the output folder was not written");
    std::fs::remove_file(out.join("openfoam")).unwrap();
    let bad = c.write("bad.stl", "solid x\nnot an stl\n");
    c.refused(&["--surface", path_str(&bad), "--formats", "vtu,calculix"], ERROR, "bad.stl");
    // A folder of the user's is refused; an empty one is taken.
    std::fs::create_dir_all(c.base.join("mine")).unwrap();
    std::fs::write(c.base.join("mine/notes.txt"), "mine").unwrap();
    c.refused(&["--output", "mine"], ERROR, "holds files vesselhex did not write");
    std::fs::create_dir_all(c.base.join("empty")).unwrap();
    assert_eq!(c.mesh(&["--output", "empty"]).code, 0);
    // Never the current folder, the root, or a folder holding an input (even with --force).
    c.refused(&["--output", ".", "--force"], ERROR, "is the current folder");
    c.refused(&["--output", "/", "--force"], ERROR, "is the root folder");
    let top = Path::new("/vesselhex-hostile-test-top-level");
    c.refused(&["--output", path_str(top), "--force"], ERROR, "is a top-level folder");
    assert!(!top.exists());
    let (stl, csv) = fixture("aaa");
    std::fs::copy(&stl, c.base.join("empty/aaa.stl")).unwrap();
    let inside = c.base.join("empty/aaa.stl");
    c.refused(
        &["--surface", path_str(&inside), "--centerlines", path_str(&csv), "--output", "empty", "--force"],
        ERROR,
        "holds the input",
    );
}

#[test]
fn links_planted_beside_the_output_are_never_followed() {
    let c = Case::new("links");
    let victim = c.base.join("victim");
    std::fs::create_dir_all(&victim).unwrap();
    // The staging names of earlier versions (pid-numbered inside the output): the folder is
    // not vesselhex's, so nothing is written, through them or at all.
    std::fs::create_dir_all(c.out()).unwrap();
    for pid in 0..64 {
        std::os::unix::fs::symlink(&victim, c.out().join(format!(".vesselhex-partial-{pid}"))).unwrap();
    }
    c.refused(&[], ERROR, "holds files vesselhex did not write");
    // Replaced with --force: the links go, the folder they point to stays empty.
    let o = c.mesh(&["--force"]);
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert_eq!(files_in(&c.out()), ["mesh.vtu", "report.json"]);
    assert!(snapshot(&victim).is_empty(), "written through a link");
    // The output itself a link: refused.
    std::os::unix::fs::symlink(&victim, c.base.join("linked")).unwrap();
    c.refused(&["--output", "linked"], ERROR, "symbolic link");
    // A staging folder left by a killed run is cleared by the next run into the same output.
    let stale = c.base.join(".out.vesselhex-AbCd1234");
    std::fs::create_dir_all(stale.join("calculix")).unwrap();
    assert_eq!(c.mesh(&[]).code, 0);
    assert!(!stale.exists(), "stale staging folder left");
    // centerlines: --branch-split naming --output's file, --output naming the surface.
    let (stl, _) = fixture("aaa");
    let copy = c.input("aaa.stl");
    std::fs::copy(&stl, &copy).unwrap();
    let before = snapshot(&c.base);
    for (args, what) in [
        (vec!["--output", "cl.vtp", "--branch-split", "./cl.vtp"], "is the same file as --output"),
        (vec!["--output", "in/aaa.stl"], "is the same file as --surface"),
    ] {
        let mut all = vec!["centerlines", "--surface", "in/aaa.stl", "--quiet"];
        all.extend(args);
        assert_refusal(&run_in(&c.base, &all), ERROR, what, &all);
    }
    assert!(before == snapshot(&c.base));
}

/// A medium mesh, finer along the vessel (about 85,000 hexes), in several formats: long enough
/// (about 1.5 s) to be caught meshing and writing.
fn long_run(c: &Case) -> Vec<String> {
    let case = c.write("long.toml", "preset = \"medium\"\n[lumen]\naxial_spacing = 0.03\n");
    let (stl, csv) = fixture("aaa");
    ["mesh", "--surface", path_str(&stl), "--centerlines", path_str(&csv), "--config", path_str(&case)]
        .into_iter()
        .map(String::from)
        .chain(["--output", "out", "--quiet", "--formats", "vtu,calculix,abaqus,febio,openfoam"].map(String::from))
        .collect()
}

/// The run's staging folder, once it exists, and whether `ready` holds for its entries.
fn wait_for_staging(c: &Case, child: &Child, ready: impl Fn(&[String]) -> bool) {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let staging = std::fs::read_dir(&c.base)
            .unwrap()
            .flatten()
            .find(|e| e.file_name().to_string_lossy().starts_with(".out.vesselhex-"));
        if let Some(s) = staging {
            let names: Vec<String> = std::fs::read_dir(s.path())
                .map(|d| d.flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect())
                .unwrap_or_default();
            if ready(&names) {
                return;
            }
        }
        assert!(Instant::now() < deadline, "the run never reached the awaited stage");
        // The child must still run, or the test cannot catch it.
        // SAFETY: peeks at our own child without reaping it.
        let mut info: libc::siginfo_t = unsafe { std::mem::zeroed() };
        let r = unsafe {
            libc::waitid(libc::P_PID, child.pid as u32, &mut info, libc::WEXITED | libc::WNOHANG | libc::WNOWAIT)
        };
        assert!(r == 0 && unsafe { info.si_pid() } == 0, "the run ended before it could be interrupted");
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Where a run is caught: meshing (its staging folder still empty) or writing (a partial file
/// in it).
#[derive(Debug, Clone, Copy)]
enum Stage {
    Meshing,
    Writing,
}

impl Stage {
    fn reached(self, staged: &[String]) -> bool {
        match self {
            Stage::Meshing => staged.is_empty(),
            Stage::Writing => staged.iter().any(|n| n.ends_with(".partial")),
        }
    }
}

#[test]
fn signals_leave_nothing_behind() {
    let c = Case::new("signals");
    let args = long_run(&c);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let cases = [
        (libc::SIGINT, Stage::Meshing),
        (libc::SIGTERM, Stage::Writing),
        (libc::SIGHUP, Stage::Meshing),
        (libc::SIGINT, Stage::Writing),
    ];
    for (k, (signal, stage)) in cases.into_iter().enumerate() {
        // Half of the runs replace an earlier result, which must stay as it was.
        if k % 2 == 1 {
            let o = c.mesh(&[]);
            assert_eq!(o.code, 0, "{}", o.stderr);
        }
        let before = snapshot(&c.base);
        let child = spawn(&args, &c.base);
        wait_for_staging(&c, &child, |staged| stage.reached(staged));
        child.signal(signal);
        let o = child.finish();
        assert_eq!(o.code, 128 + signal, "signal {signal} while {stage:?}: {}", o.stderr);
        assert!(!o.stderr.contains("panicked"), "{}", o.stderr);
        assert!(o.stderr.contains("interrupted by SIG"), "{}", o.stderr);
        let after = snapshot(&c.base);
        assert!(before == after, "signal {signal} while {stage:?} left {:?}", diff(&before, &after));
        let _ = std::fs::remove_dir_all(c.out());
    }
}

#[test]
fn concurrent_runs_into_one_folder_do_not_mix() {
    let c = Case::new("concurrent");
    let args = long_run(&c);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let first = spawn(&args, &c.base);
    wait_for_staging(&c, &first, |_| true);
    let (stl, csv) = fixture("curved");
    let second = c.mesh(&["--surface", path_str(&stl), "--centerlines", path_str(&csv)]);
    assert_refusal(&second, ERROR, "another vesselhex run is writing into this folder", &[]);
    let first = first.finish();
    assert_eq!(first.code, 0, "{}", first.stderr);
    let report = std::fs::read_to_string(c.out().join("report.json")).unwrap();
    assert!(report.contains("aaa.stl") && !report.contains("curved.stl"));
    assert_eq!(files_in(&c.out()), report_outputs(&c.out()));
}
