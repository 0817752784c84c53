//! The one-way architecture, checked from the source: every crate's modules import each other
//! without cycles, the layers below never import the layers above (the camera knows no
//! integrator, renderer or scene; the scene no camera; the optics crate no renderer), and the
//! crates depend on each other in one direction only.
//!
//! How: every `crate::…` and `super::…` path in a module's files (comments and string literals
//! stripped) is an edge from that top-level module to the one it names; grouped imports
//! (`use crate::{a, b::c}`) count each name. A cycle or a forbidden edge fails with the file and
//! the import that made it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The workspace root (this crate lives in `renderer/`).
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// Source text without comments, string and char literals (so prose and messages that mention
/// `crate::x` do not count).
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'/' && b.get(i + 1) == Some(&b'/') {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
            i += 2;
            while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                i += 1;
            }
            i += 2;
        } else if b[i] == b'r' && b.get(i + 1) == Some(&b'#') && b.get(i + 2) == Some(&b'"') {
            // raw string r#"…"#
            i += 3;
            while i + 1 < b.len() && !(b[i] == b'"' && b[i + 1] == b'#') {
                i += 1;
            }
            i += 2;
        } else if b[i] == b'\'' && b.get(i + 1) == Some(&b'\\') {
            // escaped char literal '\x'
            i += 2;
            while i < b.len() && b[i] != b'\'' {
                i += 1;
            }
            i += 1;
        } else if b[i] == b'\'' && b.get(i + 2) == Some(&b'\'') {
            // char literal 'x' (a lifetime has no closing quote there)
            i += 3;
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
        } else {
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

/// The top-level module a file belongs to (`src/camera/spec.rs` → `camera`; `lib.rs`/`main.rs`
/// → the crate root, "").
fn top_module(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap();
    let first = rel.components().next().unwrap().as_os_str().to_string_lossy().to_string();
    match first.strip_suffix(".rs") {
        Some("lib") | Some("main") => String::new(),
        Some(m) => m.to_string(),
        None => first,
    }
}

/// The names after `crate::` at each occurrence (grouped imports give several).
fn crate_paths(code: &str) -> Vec<String> {
    let mut names = Vec::new();
    for (pos, _) in code.match_indices("crate::") {
        // `$crate::` in macros and `petzval_crate::` are other things
        if pos > 0 {
            let prev = code.as_bytes()[pos - 1];
            if prev == b'$' || prev.is_ascii_alphanumeric() || prev == b'_' {
                continue;
            }
        }
        let rest = &code[pos + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // first-level names inside the braces
            let mut depth = 0;
            let mut current = String::new();
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        names.push(std::mem::take(&mut current));
                    }
                    _ if depth == 0 => current.push(c),
                    _ => {}
                }
            }
            names.push(current);
        } else {
            names.push(rest.to_string());
        }
    }
    names
        .into_iter()
        .filter_map(|n| {
            let n = n.trim();
            let ident: String = n.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            (!ident.is_empty() && ident.chars().next().unwrap().is_ascii_lowercase()).then_some(ident)
        })
        .collect()
}

/// Edges `module → module` of one crate's `src/`, with one example import for each.
fn module_graph(src: &Path) -> BTreeMap<(String, String), String> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    assert!(!files.is_empty(), "no Rust files under {}", src.display());
    let modules: BTreeSet<String> = files.iter().map(|f| top_module(src, f)).collect();
    let mut edges = BTreeMap::new();
    for f in &files {
        let from = top_module(src, f);
        let code = code_only(&std::fs::read_to_string(f).unwrap());
        for to in crate_paths(&code) {
            if to != from && modules.contains(&to) && !from.is_empty() {
                edges
                    .entry((from.clone(), to.clone()))
                    .or_insert_with(|| format!("{} imports crate::{to}", f.strip_prefix(root()).unwrap().display()));
            }
        }
    }
    edges
}

/// Edges between the files of one module folder (`camera/spec.rs` → `camera/model_choice.rs`
/// through `super::model_choice` or `crate::camera::model_choice`).
fn submodule_graph(src: &Path, folder: &Path) -> BTreeMap<(String, String), String> {
    let module = folder.file_name().unwrap().to_string_lossy().to_string();
    let mut files: Vec<PathBuf> = std::fs::read_dir(folder)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    files.sort();
    let name = |p: &Path| p.file_stem().unwrap().to_string_lossy().to_string();
    let children: BTreeSet<String> = files.iter().map(|f| name(f)).filter(|n| n != "mod").collect();
    let mut edges = BTreeMap::new();
    for f in &files {
        let from = name(f);
        if from == "mod" {
            continue;
        }
        let code = code_only(&std::fs::read_to_string(f).unwrap());
        let via_super = code.match_indices("super::").map(|(i, _)| &code[i + "super::".len()..]);
        let prefix = format!("crate::{module}::");
        let via_crate = code.match_indices(prefix.as_str()).map(|(i, _)| &code[i + prefix.len()..]);
        for rest in via_super.chain(via_crate) {
            let mut targets = Vec::new();
            if let Some(group) = rest.strip_prefix('{') {
                let inner: String = group.chars().take_while(|c| *c != '}').collect();
                targets.extend(inner.split(',').map(|t| t.trim().to_string()));
            } else {
                targets.push(rest.to_string());
            }
            for t in targets {
                let ident: String = t.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
                if ident != from && children.contains(&ident) {
                    edges.entry((from.clone(), ident.clone())).or_insert_with(|| {
                        format!("{} imports {module}::{ident}", f.strip_prefix(root()).unwrap().display())
                    });
                }
            }
        }
    }
    let _ = src;
    edges
}

/// Every module folder under `src` (recursively).
fn module_folders(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut dirs: Vec<PathBuf> = entries.flatten().map(|e| e.path()).filter(|p| p.is_dir()).collect();
    dirs.sort();
    for d in dirs {
        out.push(d.clone());
        module_folders(&d, out);
    }
}

/// A cycle among the edges, if any (depth-first search).
fn find_cycle(edges: &BTreeMap<(String, String), String>) -> Option<Vec<String>> {
    let mut next: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (a, b) in edges.keys() {
        next.entry(a).or_default().push(b);
    }
    fn visit<'a>(
        n: &'a str,
        next: &BTreeMap<&'a str, Vec<&'a str>>,
        state: &mut BTreeMap<&'a str, u8>,
        stack: &mut Vec<&'a str>,
    ) -> Option<Vec<String>> {
        match state.get(n) {
            Some(2) => return None,
            Some(1) => {
                let start = stack.iter().position(|s| *s == n).unwrap();
                let mut cycle: Vec<String> = stack[start..].iter().map(|s| s.to_string()).collect();
                cycle.push(n.to_string());
                return Some(cycle);
            }
            _ => {}
        }
        state.insert(n, 1);
        stack.push(n);
        for m in next.get(n).into_iter().flatten() {
            if let Some(c) = visit(m, next, state, stack) {
                return Some(c);
            }
        }
        stack.pop();
        state.insert(n, 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in next.keys() {
        if let Some(c) = visit(n, &next, &mut state, &mut Vec::new()) {
            return Some(c);
        }
    }
    None
}

/// Every crate of the workspace with its source folder.
fn crate_sources() -> Vec<(&'static str, PathBuf)> {
    let r = root();
    let mut crates = vec![
        ("petzval", r.join("src")),
        ("petzval-renderer", r.join("renderer/src")),
        ("petzval-optics", r.join("renderer/optics/src")),
    ];
    for (name, dir) in
        [("petzval-blender", "blender_addon/src"), ("petzval-usd", "usd/src"), ("petzval-fit", "lens-fit/src")]
    {
        if r.join(dir).is_dir() {
            crates.push((name, r.join(dir)));
        }
    }
    crates
}

#[test]
fn no_module_cycles_in_any_crate() {
    for (name, src) in crate_sources() {
        let edges = module_graph(&src);
        if let Some(cycle) = find_cycle(&edges) {
            let why: Vec<String> = cycle.windows(2).map(|w| edges[&(w[0].clone(), w[1].clone())].clone()).collect();
            panic!("{name}: module cycle {}:\n  {}", cycle.join(" → "), why.join("\n  "));
        }
        let mut folders = Vec::new();
        module_folders(&src, &mut folders);
        for folder in folders {
            let edges = submodule_graph(&src, &folder);
            if let Some(cycle) = find_cycle(&edges) {
                let why: Vec<String> = cycle.windows(2).map(|w| edges[&(w[0].clone(), w[1].clone())].clone()).collect();
                panic!(
                    "{name}: cycle between the files of {}: {}:\n  {}",
                    folder.strip_prefix(root()).unwrap().display(),
                    cycle.join(" → "),
                    why.join("\n  ")
                );
            }
        }
    }
}

#[test]
fn lower_layers_never_import_upper_ones() {
    // (module, modules it must not import) in petzval-renderer
    let forbidden: &[(&str, &[&str])] = &[
        ("camera", &["integrator", "render", "scene", "film"]),
        ("scene", &["camera", "integrator", "render"]),
        ("integrator", &["camera", "render", "film"]),
        ("film", &["camera", "integrator", "render"]),
        ("sampler", &["camera", "integrator", "render", "scene", "film"]),
        ("spectral", &["camera", "integrator", "render", "scene", "film"]),
    ];
    let edges = module_graph(&root().join("renderer/src"));
    let mut bad = Vec::new();
    for (from, tos) in forbidden {
        for to in *tos {
            if let Some(why) = edges.get(&(from.to_string(), to.to_string())) {
                bad.push(why.clone());
            }
        }
    }
    assert!(bad.is_empty(), "imports against the data flow:\n  {}", bad.join("\n  "));
}

#[test]
fn crates_depend_one_way() {
    // Each crate's manifest may name only crates below it.
    let r = root();
    let deps = |manifest: &str| -> String {
        let text = std::fs::read_to_string(r.join(manifest)).unwrap();
        // the [dependencies] tables only (dev-dependencies may use anything below too)
        text.split("\n[").filter(|s| s.starts_with("dependencies") || s.starts_with("target.")).collect()
    };
    let optics = deps("renderer/optics/Cargo.toml");
    for upper in ["petzval-renderer", "petzval-usd", "petzval-fit", "petzval-blender", "pyo3"] {
        assert!(!optics.contains(upper), "petzval-optics must not depend on {upper}");
    }
    let renderer = deps("renderer/Cargo.toml");
    for upper in ["petzval-usd", "petzval-fit", "petzval-blender", "pyo3"] {
        assert!(!renderer.contains(upper), "petzval-renderer must not depend on {upper}");
    }
    if r.join("lens-fit/Cargo.toml").is_file() {
        let fit = deps("lens-fit/Cargo.toml");
        assert!(!fit.contains("petzval-renderer"), "lens-fit depends on petzval-optics only");
    }
}

#[test]
fn the_checker_sees_a_cycle_and_grouped_imports() {
    // The checker itself: grouped imports count each name; comments and strings do not count.
    let code = code_only("use crate::{camera::Camera, film};\n// crate::render\nlet s = \"crate::scene\";");
    assert_eq!(crate_paths(&code), vec!["camera".to_string(), "film".to_string()]);
    let mut edges = BTreeMap::new();
    edges.insert(("a".to_string(), "b".to_string()), String::new());
    edges.insert(("b".to_string(), "c".to_string()), String::new());
    assert_eq!(find_cycle(&edges), None);
    edges.insert(("c".to_string(), "a".to_string()), String::new());
    assert!(find_cycle(&edges).is_some());
}
