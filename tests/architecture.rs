//! The shape of `src/`, read as text (nothing is compiled or run):
//!
//! - the modules import downwards only: the graph of `use crate::…`, `crate::…::` and
//!   `super::…` references between the top-level modules, and between the stages under
//!   `src/stages/`, has no cycle, and the top-level modules keep the order of the layers
//!   (docs/ARCHITECTURE.md);
//! - no function in `src/` is longer than [`MAX_FUNCTION_LINES`] lines.
//!
//! Test code (`#[cfg(test)]` modules) is left out of the graph: a unit test may build its input
//! with anything, the `testing` helpers and the pipeline included, as integration tests do.
//! The binary (`src/main.rs`) reaches the library as `vesselhex::…` and stands above it all.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The longest a function may be, from its `fn` line to its closing brace, both counted.
const MAX_FUNCTION_LINES: usize = 150;

/// The layers, from the bottom up. A module may import its own layer's siblings (without a
/// cycle) and the layers below it, never one above.
const LAYERS: &[&[&str]] = &[
    &["data"],
    &["geometry"],
    &["io"],
    &["stages"],
    &["writers"],
    &["pipeline"],
    &[
        "implicit_surface",
        "synthetic",
        "synthetic_branching",
        "synthetic_tree",
        "synthetic_network",
        "testing",
        "batch",
    ],
];

/// The stages under `src/stages/`, in the order data flows through them: a stage may import
/// the stages before it, never one after.
const STAGES: &[&str] = &["centerline", "junction", "projection", "volume", "annotation", "additions"];

/// A source file: its path under `src/`, its module path and its code with comments, strings
/// and character literals blanked (newlines kept, so that line numbers hold).
struct Source {
    file: String,
    module: Vec<String>,
    code: String,
}

fn sources() -> Vec<Source> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    collect_rust_files(&src, &mut files);
    files.sort();
    files
        .iter()
        .map(|path| {
            let file = path.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
            let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            Source { module: module_of(&file), code: blank_comments_and_literals(&text), file }
        })
        .collect()
}

fn collect_rust_files(dir: &Path, files: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.is_dir() {
            collect_rust_files(&path, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}

/// `stages/junction/mod.rs` -> `[stages, junction]`; `lib.rs` and `main.rs` -> `[]`.
fn module_of(file: &str) -> Vec<String> {
    let mut parts: Vec<String> = file.trim_end_matches(".rs").split('/').map(str::to_string).collect();
    if parts.len() == 1 && (parts[0] == "lib" || parts[0] == "main") || parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// The code with every comment, string and character literal replaced by spaces (a string
/// keeps its quotes), so that neither a brace nor a path inside one is taken for code.
fn blank_comments_and_literals(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let mut i = 0;
    while i < b.len() {
        let ident_before = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if b[i..].starts_with(b"//") {
            let end = b[i..].iter().position(|&c| c == b'\n').map_or(b.len(), |p| i + p);
            blank(&mut out, i, end);
            i = end;
        } else if b[i..].starts_with(b"/*") {
            let (mut depth, mut j) = (0, i);
            while j < b.len() {
                if b[j..].starts_with(b"/*") {
                    depth += 1;
                    j += 2;
                } else if b[j..].starts_with(b"*/") {
                    depth -= 1;
                    j += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    j += 1;
                }
            }
            blank(&mut out, i, j);
            i = j;
        } else if let Some(hashes) = raw_string_start(b, i).filter(|_| !ident_before) {
            let open = b[i..].iter().position(|&c| c == b'"').unwrap() + i + 1;
            let close: Vec<u8> = std::iter::once(b'"').chain(std::iter::repeat(b'#').take(hashes)).collect();
            let end = b[open..].windows(close.len()).position(|w| w == close).expect("a closed raw string") + open;
            blank(&mut out, open, end);
            i = end + close.len();
        } else if b[i] == b'"' {
            let mut j = i + 1;
            while b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            blank(&mut out, i + 1, j);
            i = j + 1;
        } else if b[i] == b'\'' {
            // A character literal ('x', '\n', '\u{7f}', '"'); otherwise a lifetime or a label.
            let len = if b.get(i + 1) == Some(&b'\\') {
                b[i + 2..].iter().position(|&c| c == b'\'').map(|p| p + 3)
            } else {
                let width = text[i + 1..].chars().next().map_or(1, char::len_utf8);
                (b.get(i + 1 + width) == Some(&b'\'')).then_some(width + 2)
            };
            let len = len.unwrap_or(1);
            blank(&mut out, i, i + len);
            i += len;
        } else {
            i += 1;
        }
    }
    String::from_utf8(out).expect("blanking keeps UTF-8: only whole literals and comments are blanked")
}

/// At `r"`, `r#"`, `br"`, …: the number of `#`.
fn raw_string_start(b: &[u8], i: usize) -> Option<usize> {
    let mut j = i;
    if b.get(j) == Some(&b'b') {
        j += 1;
    }
    if b.get(j) != Some(&b'r') {
        return None;
    }
    j += 1;
    let hashes = b[j..].iter().take_while(|&&c| c == b'#').count();
    (b.get(j + hashes) == Some(&b'"')).then_some(hashes)
}

fn is_ident_byte(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// The byte offsets of `word` standing as a whole word in `code`.
fn word_positions<'a>(code: &'a str, word: &'a str) -> impl Iterator<Item = usize> + 'a {
    let b = code.as_bytes();
    code.match_indices(word).map(|(i, _)| i).filter(move |&i| {
        (i == 0 || !is_ident_byte(b[i - 1])) && b.get(i + word.len()).is_none_or(|&c| !is_ident_byte(c))
    })
}

/// The index of the brace closing the one at `open`.
fn matching_brace(code: &[u8], open: usize) -> usize {
    let mut depth = 0usize;
    for (i, &c) in code.iter().enumerate().skip(open) {
        match c {
            b'{' => depth += 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    return i;
                }
            }
            _ => {}
        }
    }
    panic!("unbalanced braces")
}

/// An inline module (`mod name { … }`) of a file: its name, its byte range, and whether it is
/// test code (`#[cfg(test)]` just before it).
struct InlineModule {
    name: String,
    range: std::ops::Range<usize>,
    test_only: bool,
}

fn inline_modules(code: &str) -> Vec<InlineModule> {
    let b = code.as_bytes();
    let mut found = Vec::new();
    for at in word_positions(code, "mod") {
        let rest = &code[at + 3..];
        let name: String = rest.trim_start().chars().take_while(|&c| c.is_alphanumeric() || c == '_').collect();
        let after_name = rest.trim_start()[name.len()..].trim_start();
        if name.is_empty() || !after_name.starts_with('{') {
            continue;
        }
        let open = code.len() - after_name.len();
        let before = code[..at].trim_end().trim_end_matches("pub").trim_end();
        let test_only = before.ends_with("#[cfg(test)]");
        found.push(InlineModule { name, range: at..matching_brace(b, open) + 1, test_only });
    }
    found
}

/// Every `use` tree's paths, expanded (`a::{b, c::d}` -> `a::b`, `a::c::d`), with the byte
/// offset of its `use`; and the code with the `use` items blanked.
fn use_paths(code: &str) -> (Vec<(usize, Vec<String>)>, String) {
    let mut paths = Vec::new();
    let mut rest = code.as_bytes().to_vec();
    for at in word_positions(code, "use") {
        let end = code[at..].find(';').map_or(code.len(), |p| at + p);
        let tree = code[at + 3..end].split_whitespace().collect::<Vec<_>>().join(" ");
        for (path, _) in expand_use_tree(&tree) {
            paths.push((at, path));
        }
        for c in &mut rest[at..end] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    }
    (paths, String::from_utf8(rest).unwrap())
}

/// Each path of a `use` tree, with the name it brings in (its last segment, or its rename).
fn expand_use_tree(tree: &str) -> Vec<(Vec<String>, String)> {
    let segments = |path: &str| -> Vec<String> {
        path.split("::").map(str::trim).filter(|s| !s.is_empty()).map(str::to_string).collect()
    };
    let mut paths = Vec::new();
    for part in split_top_level(tree) {
        if let (Some(open), Some(close)) = (part.find('{'), part.rfind('}')) {
            let head = segments(&part[..open]);
            for (tail, name) in expand_use_tree(&part[open + 1..close]) {
                paths.push((head.iter().cloned().chain(tail).collect(), name));
            }
        } else {
            // `a::b as c`: the path is `a::b`, the name `c`.
            let words: Vec<&str> = part.split(' ').collect();
            let path = segments(words[0]);
            let name = if words.len() == 3 && words[1] == "as" {
                words[2].to_string()
            } else {
                path.last().cloned().unwrap_or_default()
            };
            paths.push((path, name));
        }
    }
    paths
}

fn split_top_level(tree: &str) -> Vec<&str> {
    let (mut parts, mut depth, mut start) = (Vec::new(), 0, 0);
    for (i, c) in tree.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&tree[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&tree[start..]);
    parts.into_iter().map(str::trim).filter(|p| !p.is_empty()).collect()
}

/// A reference from one module to another: where it stands (`file:line`) and the absolute
/// module path it names (`crate::` left off).
struct Reference {
    from: Vec<String>,
    to: Vec<String>,
    place: String,
}

/// Every reference of the library's non-test code to a path of the crate, resolved to an
/// absolute path (relative `super::`/`self::` paths and the root's re-exports followed).
fn references(sources: &[Source]) -> Vec<Reference> {
    let top: BTreeSet<String> = sources.iter().filter(|s| s.module.len() == 1).map(|s| s.module[0].clone()).collect();
    let root = sources.iter().find(|s| s.file == "lib.rs").expect("src/lib.rs");
    // `pub use data::{config, error};` in lib.rs: `crate::config` is `crate::data::config`.
    let mut aliases: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for at in word_positions(&root.code, "use") {
        let end = root.code[at..].find(';').map_or(root.code.len(), |p| at + p);
        let tree = root.code[at + 3..end].split_whitespace().collect::<Vec<_>>().join(" ");
        for (path, name) in expand_use_tree(&tree) {
            let path = if path.first().is_some_and(|p| p == "crate") { path[1..].to_vec() } else { path };
            aliases.insert(name, path);
        }
    }
    let mut found = Vec::new();
    for source in sources.iter().filter(|s| s.file != "main.rs" && !s.file.starts_with("bin/")) {
        let modules = inline_modules(&source.code);
        let (uses, code) = use_paths(&source.code);
        let mut paths: Vec<(usize, Vec<String>)> = uses;
        for keyword in ["crate", "super", "self"] {
            for at in word_positions(&code, keyword) {
                let path: Vec<String> = code[at..]
                    .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                    .next()
                    .unwrap_or_default()
                    .split("::")
                    .map(str::to_string)
                    .collect();
                if path.len() > 1 {
                    paths.push((at, path));
                }
            }
        }
        for (at, path) in paths {
            let enclosing: Vec<&InlineModule> = modules.iter().filter(|m| m.range.contains(&at)).collect();
            if enclosing.iter().any(|m| m.test_only) {
                continue;
            }
            let mut here = source.module.clone();
            let mut inline: Vec<&InlineModule> = enclosing;
            inline.sort_by_key(|m| m.range.start);
            here.extend(inline.iter().map(|m| m.name.clone()));
            let Some(mut to) = absolute(&path, &here, &top) else { continue };
            if let Some(target) = to.first().and_then(|first| aliases.get(first)).filter(|_| !top.contains(&to[0])) {
                to = target.iter().cloned().chain(to[1..].iter().cloned()).collect();
            }
            let line = source.code[..at].matches('\n').count() + 1;
            found.push(Reference { from: source.module.clone(), to, place: format!("src/{}:{line}", source.file) });
        }
    }
    found
}

/// `path` as seen from module `here`, made absolute; `None` for a path outside the crate.
fn absolute(path: &[String], here: &[String], top: &BTreeSet<String>) -> Option<Vec<String>> {
    match path[0].as_str() {
        "crate" => Some(path[1..].to_vec()),
        "super" | "self" => {
            let mut base = here.to_vec();
            let mut rest = path;
            while let Some(first) = rest.first().filter(|p| *p == "super" || *p == "self") {
                if first == "super" {
                    base.pop();
                }
                rest = &rest[1..];
            }
            Some(base.into_iter().chain(rest.iter().cloned()).collect())
        }
        // In the crate's root, `use data::x` names the module `data`.
        first if here.is_empty() && top.contains(first) => Some(path.to_vec()),
        _ => None,
    }
}

/// The edges between the nodes `node` gives (a module path's node, if it has one), each with
/// the first place that makes it.
fn graph(
    references: &[Reference],
    node: impl Fn(&[String]) -> Option<String>,
) -> BTreeMap<String, BTreeMap<String, String>> {
    let mut edges: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for reference in references {
        if let (Some(from), Some(to)) = (node(&reference.from), node(&reference.to)) {
            if from != to {
                edges.entry(from).or_default().entry(to).or_insert_with(|| reference.place.clone());
            }
        }
    }
    edges
}

/// One cycle of the graph, as its nodes in order (the first repeated at the end), if any.
fn find_cycle(edges: &BTreeMap<String, BTreeMap<String, String>>) -> Option<Vec<String>> {
    // Depth first; a node met again while still on the path closes a cycle.
    fn visit(
        node: &str,
        edges: &BTreeMap<String, BTreeMap<String, String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(start) = path.iter().position(|n| n == node) {
            let mut cycle = path[start..].to_vec();
            cycle.push(node.to_string());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in edges.get(node).into_iter().flat_map(BTreeMap::keys) {
            if let Some(cycle) = visit(next, edges, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    edges.keys().find_map(|node| visit(node, edges, &mut Vec::new(), &mut done))
}

fn describe_cycle(cycle: &[String], edges: &BTreeMap<String, BTreeMap<String, String>>) -> String {
    let steps: Vec<String> =
        cycle.windows(2).map(|w| format!("  {} -> {} ({})", w[0], w[1], edges[&w[0]][&w[1]])).collect();
    format!("a cycle of imports: {}\n{}", cycle.join(" -> "), steps.join("\n"))
}

fn assert_acyclic(level: &str, edges: &BTreeMap<String, BTreeMap<String, String>>) {
    if let Some(cycle) = find_cycle(edges) {
        panic!("{level}: {}", describe_cycle(&cycle, edges));
    }
}

#[test]
fn top_level_modules_import_downwards_only() {
    let sources = sources();
    let references = references(&sources);
    let edges = graph(&references, |path| path.first().cloned());
    assert!(edges.contains_key("pipeline"), "the reader found no imports at all: {edges:?}");
    assert_acyclic("the top-level modules of src/", &edges);
    let layer_of = |module: &str| LAYERS.iter().position(|layer| layer.contains(&module));
    assert_downwards("top-level module", &edges, layer_of);
}

/// Every edge goes from a node to one of the same rank or below; a node `rank` does not know
/// fails the test, naming it.
fn assert_downwards(
    kind: &str,
    edges: &BTreeMap<String, BTreeMap<String, String>>,
    rank: impl Fn(&str) -> Option<usize>,
) {
    let mut upwards = Vec::new();
    for (from, targets) in edges {
        let from_rank = rank(from)
            .unwrap_or_else(|| panic!("{kind} {from}: in no layer (add it to this test and docs/ARCHITECTURE.md)"));
        for (to, place) in targets {
            let to_rank = rank(to).unwrap_or_else(|| panic!("{place}: {kind} {to}: in no layer"));
            if to_rank > from_rank {
                upwards.push(format!("  {from} imports {to}, which stands above it ({place})"));
            }
        }
    }
    assert!(upwards.is_empty(), "imports that go upwards:\n{}", upwards.join("\n"));
}

#[test]
fn stages_import_only_the_stages_before_them() {
    let sources = sources();
    let references = references(&sources);
    let edges = graph(&references, |path| (path.len() > 1 && path[0] == "stages").then(|| path[1].clone()));
    assert!(edges.contains_key("volume"), "the reader found no imports between the stages: {edges:?}");
    assert_acyclic("the stages under src/stages/", &edges);
    assert_downwards("stage", &edges, |stage| STAGES.iter().position(|s| *s == stage));
}

/// Each function of the sources, as (lines, `file:line`, name).
fn function_lengths(sources: &[Source]) -> Vec<(usize, String, String)> {
    let mut found = Vec::new();
    for source in sources {
        let code = source.code.as_bytes();
        for at in word_positions(&source.code, "fn") {
            let name: String =
                source.code[at + 2..].trim_start().chars().take_while(|&c| c.is_alphanumeric() || c == '_').collect();
            // The body opens at the first `{` after the signature; a `;` first means no body.
            let Some(open) = source.code[at..].find(['{', ';']).map(|p| at + p).filter(|&p| code[p] == b'{') else {
                continue;
            };
            if name.is_empty() {
                continue; // `fn(…)` types: a `{` after them belongs to something else
            }
            let close = matching_brace(code, open);
            let first = source.code[..at].matches('\n').count() + 1;
            let last = source.code[..close].matches('\n').count() + 1;
            found.push((last - first + 1, format!("src/{}:{first}", source.file), name));
        }
    }
    found.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    found
}

#[test]
fn no_function_is_longer_than_the_limit() {
    let sources = sources();
    let lengths = function_lengths(&sources);
    assert!(lengths.len() > 500, "the reader found only {} functions", lengths.len());
    let too_long: Vec<String> = lengths
        .iter()
        .filter(|(lines, _, _)| *lines > MAX_FUNCTION_LINES)
        .map(|(lines, place, name)| format!("  {name} ({place}): {lines} lines"))
        .collect();
    let longest: Vec<String> =
        lengths.iter().take(5).map(|(lines, place, name)| format!("{name} ({place}): {lines}")).collect();
    assert!(
        too_long.is_empty(),
        "functions longer than {MAX_FUNCTION_LINES} lines (split them into named steps):\n{}\nthe longest: {}",
        too_long.join("\n"),
        longest.join("; ")
    );
}

#[test]
fn the_reader_sees_paths_and_functions_as_rust_does() {
    let code = blank_comments_and_literals(
        "use crate::{a::b, c::{d as e, f}};\n// crate::x::y\nfn f() { let s = \"}crate::z\"; let c = '{'; }\nfn g<'a>(x: &'a str) {}\n",
    );
    let (uses, rest) = use_paths(&code);
    let paths: Vec<String> = uses.iter().map(|(_, p)| p.join("::")).collect();
    assert_eq!(paths, ["crate::a::b", "crate::c::d", "crate::c::f"]);
    assert!(!rest.contains("crate::"), "comments and strings are blanked: {rest}");
    let source = Source { file: "x.rs".into(), module: vec!["x".into()], code };
    let lengths: Vec<(usize, String)> = function_lengths(&[source]).into_iter().map(|(n, _, name)| (n, name)).collect();
    assert_eq!(lengths, [(1, "f".to_string()), (1, "g".to_string())]);
    let mut edges: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for (a, b) in [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")] {
        edges.entry(a.into()).or_default().insert(b.into(), format!("{a}.rs:1"));
    }
    assert_eq!(find_cycle(&edges).unwrap(), ["a", "b", "c", "a"]);
    edges.get_mut("c").unwrap().remove("a");
    assert_eq!(find_cycle(&edges), None);
}
