//! The docs as checked claims: docs/SCENARIO.md's key tables are the ones
//! the code generates, every cited work has its entry in
//! docs/REFERENCES.md, every relative link between the pages resolves, and
//! `src/`'s top-level modules import only the layers below them, in the
//! order ARCHITECTURE.md states.
//!
//! `SKINPATCH_UPDATE_DOCS=1` rewrites SCENARIO.md's tables from the code.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use skinpatch::scenario::reference::{markdown, tables, Table};
use skinpatch::scenario::{FitSamples, Scenario, SynthFile};

use crate::common::root;
use crate::readme::DOCS;

/// The input files whose keys docs/SCENARIO.md documents, with the name
/// its markers give them.
fn generated() -> Vec<(&'static str, Vec<Table>)> {
    vec![
        ("scenario", tables::<Scenario>()),
        ("synth", tables::<SynthFile>()),
        ("fit", tables::<FitSamples>()),
    ]
}

/// The marker opening a generated table: `<!-- keys FILE SECTION -->`.
fn marker(file: &str, table: &Table) -> String {
    let section = if table.section.is_empty() {
        "top"
    } else {
        &table.section
    };
    format!("<!-- keys {file} {section} -->")
}

const END: &str = "<!-- /keys -->";

/// docs/SCENARIO.md holds, between its markers, exactly the tables the
/// code generates: a key added, renamed or given another default without
/// its entry fails here (`SKINPATCH_UPDATE_DOCS=1` rewrites the tables; a
/// new section needs its marker placed by hand, where its prose is).
#[test]
fn scenario_reference_matches_the_code() {
    let path = root().join("docs/SCENARIO.md");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut wanted = BTreeMap::new();
    let mut in_comments = Vec::new();
    for (file, list) in generated() {
        for table in list {
            for row in &table.rows {
                assert!(
                    !row.meaning.is_empty(),
                    "{file} {} `{}` has no doc comment to document it",
                    table.section,
                    row.key
                );
                // A default that is a value lives in the code once: in
                // `Default`, or for an `Option` the validation fills in,
                // in a constant the validation uses and the field's
                // `#[schemars(extend("default" = …))]` states.
                let plain = row.default.trim_matches('`');
                if row.default_from_comment
                    && toml::from_str::<toml::Table>(&format!("v = {plain}")).is_ok()
                {
                    in_comments.push(format!("{file} {} {}", table.section, row.key));
                }
            }
            wanted.insert(marker(file, &table), markdown(&[table]));
        }
    }
    assert!(
        in_comments.is_empty(),
        "these keys state their default only in a doc comment: put it in a constant used by \
         the validation and by #[schemars(extend(\"default\" = …))]: {in_comments:#?}"
    );
    let mut updated = String::new();
    let mut rest = text.as_str();
    let mut seen = BTreeSet::new();
    let mut stale = Vec::new();
    while let Some(start) = rest.find("<!-- keys ") {
        let open_end = start + rest[start..].find("-->").expect("marker closes") + 3;
        let open = &rest[start..open_end];
        let close = open_end + rest[open_end..].find(END).expect("table block closes");
        let body = &rest[open_end..close];
        updated += &rest[..open_end];
        match wanted.get(open) {
            Some(table) => {
                let fresh = format!("\n\n{table}");
                if body != fresh {
                    stale.push(open.to_string());
                }
                updated += &fresh;
            }
            None => panic!("{open} in docs/SCENARIO.md names no section the code has"),
        }
        assert!(seen.insert(open.to_string()), "{open} twice");
        rest = &rest[close..];
    }
    updated += rest;
    let missing: Vec<&String> = wanted.keys().filter(|k| !seen.contains(*k)).collect();
    assert!(
        missing.is_empty(),
        "docs/SCENARIO.md lacks these sections: place each marker where its prose is, \
         followed by {END}, then run with SKINPATCH_UPDATE_DOCS=1: {missing:#?}"
    );
    if std::env::var("SKINPATCH_UPDATE_DOCS").is_ok_and(|v| v == "1") {
        std::fs::write(&path, updated).unwrap();
        return;
    }
    assert!(
        stale.is_empty(),
        "docs/SCENARIO.md's tables differ from the code (run this test with \
         SKINPATCH_UPDATE_DOCS=1 to rewrite them): {stale:#?}"
    );
}

/// The tables are complete for keys the parser takes: a few keys from
/// every corner of the format, each in its section's table.
#[test]
fn the_generated_tables_hold_keys_from_every_corner() {
    let all = generated();
    let find = |file: &str, section: &str, key: &str| {
        let (_, list) = all.iter().find(|(f, _)| *f == file).unwrap();
        let table = list
            .iter()
            .find(|t| t.section == section)
            .unwrap_or_else(|| panic!("{file}: no section {section}"));
        table
            .rows
            .iter()
            .find(|r| r.key == key)
            .unwrap_or_else(|| panic!("{file} {section}: no key {key}"))
            .clone()
    };
    let mix = find("scenario", "[render]", "mix_ratio");
    assert_eq!((mix.kind.as_str(), mix.default.as_str()), ("number", "0.5"));
    let width = find("scenario", "[render]", "width_px");
    assert_eq!(
        (width.kind.as_str(), width.default.as_str()),
        ("integer", "640")
    );
    let model = find("scenario", "[material.<name>]", "model");
    assert!(model.kind.contains("\"corotational\""), "{model:?}");
    let intensity = find("scenario", "[[render.lights]]", "intensity");
    assert_eq!(intensity.kind, "number");
    find("scenario", "[mesh.refine]", "max_volume_mm3");
    find("scenario", "[probe]", "path_mm");
    find("synth", "[synthesis]", "exemplar");
    find("fit", "[[sample]]", "r");
}

/// The works cited in code and docs as a surname and a year, a surname
/// with "et al." and a year, or surnames joined by "&" and a year: the
/// surname before the year.
fn citations(text: &str) -> BTreeSet<(String, String)> {
    let mut found = BTreeSet::new();
    let words: Vec<&str> = text.split_whitespace().collect();
    for (i, w) in words.iter().enumerate() {
        let year: String = w.chars().filter(char::is_ascii_digit).collect();
        let clean = w.trim_matches(|c: char| !c.is_ascii_digit());
        if clean.len() != 4
            || year.len() != 4
            || !(year.starts_with("19") || year.starts_with("20"))
        {
            continue;
        }
        if i == 0 {
            continue;
        }
        let mut name = words[i - 1];
        if name == "al." && i >= 3 && words[i - 2] == "et" {
            name = words[i - 3];
        }
        let name = name.trim_matches(|c: char| !c.is_alphabetic() && c != '\'');
        let capitalised = name.chars().next().is_some_and(char::is_uppercase)
            && name
                .chars()
                .skip(1)
                .all(|c| c.is_lowercase() || c == '\'' || c == '-');
        if capitalised && name.chars().count() > 2 && !NOT_AUTHORS.contains(&name) {
            found.insert((name.to_string(), year));
        }
    }
    found
}

/// Capitalised words that stand before a year without naming an author.
const NOT_AUTHORS: &[&str] = &[
    "Blender",
    "Debian",
    "Graphics",
    "Eurographics",
    "Interface",
    "Conference",
    "Talks",
    "January",
    "Python",
    "Ubuntu",
    "Pergamon",
    "Forum",
    "Grace",
    "Cathedral",
    "Asia",
    "Computing",
    "Engineering",
    "Wisconsin",
    "Mathematik",
    "Rendering",
    "Software",
    "Animation",
    "Applications",
    "Madison",
    "Games",
    "Environments",
    "Since",
    "Until",
];

/// Every author–year citation of the code, shaders, Python, examples and
/// pages has an entry in docs/REFERENCES.md whose key names that author
/// and year.
#[test]
fn every_citation_has_a_reference() {
    let refs = std::fs::read_to_string(root().join("docs/REFERENCES.md")).unwrap();
    let keys: Vec<&str> = refs
        .lines()
        .filter_map(|l| l.strip_prefix("- **"))
        .filter_map(|l| l.split("**").next())
        .collect();
    let mut texts = Vec::new();
    for dir in ["src", "shaders", "python", "examples", "tests"] {
        collect(&root().join(dir), &mut texts);
    }
    for page in DOCS {
        texts.push((
            page.to_string(),
            std::fs::read_to_string(root().join(page)).unwrap(),
        ));
    }
    let mut unknown = Vec::new();
    for (file, text) in &texts {
        for (name, year) in citations(text) {
            if !keys.iter().any(|k| k.contains(&name) && k.contains(&year)) {
                unknown.push(format!("{name} {year} ({file})"));
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "cited without an entry in docs/REFERENCES.md: {unknown:#?}"
    );
}

/// The text files under `dir` (sources, shaders, scripts, scenarios).
fn collect(dir: &Path, out: &mut Vec<(String, String)>) {
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        if path.is_dir() {
            collect(&path, out);
        } else if path.extension().is_some_and(|e| {
            ["rs", "wgsl", "py", "pyi", "toml", "md"].contains(&e.to_str().unwrap())
        }) {
            if let Ok(text) = std::fs::read_to_string(&path) {
                out.push((path.display().to_string(), text));
            }
        }
    }
}

/// Every relative link of the pages (`[text](path)`, `![alt](path)`)
/// names a file or folder that exists, and a `#anchor` into a page names
/// one of its headings.
#[test]
fn links_between_the_pages_resolve() {
    let mut broken = Vec::new();
    for page in DOCS {
        let text = std::fs::read_to_string(root().join(page)).unwrap();
        let base = root().join(page).parent().unwrap().to_path_buf();
        for link in links(&text) {
            if link.contains("://") || link.starts_with("mailto:") {
                continue;
            }
            let (file, anchor) = link.split_once('#').unwrap_or((&link, ""));
            let target = if file.is_empty() {
                root().join(page)
            } else {
                base.join(file)
            };
            if !target.exists() {
                broken.push(format!("{page}: {link}"));
                continue;
            }
            if !anchor.is_empty() {
                let body = std::fs::read_to_string(&target).unwrap_or_default();
                if !headings(&body).contains(anchor) {
                    broken.push(format!("{page}: {link} (no such heading)"));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links: {broken:#?}");
}

/// The targets of the Markdown links in `text`, code spans and blocks left out.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_code = false;
    for line in text.lines() {
        if line.starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            continue;
        }
        let line: String = line.split('`').step_by(2).collect::<Vec<_>>().join("");
        let mut rest = line.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            out.push(after[..end].to_string());
            rest = &after[end..];
        }
    }
    out
}

/// GitHub's anchors of the headings of `text`: lower case, spaces as `-`,
/// punctuation other than `-` and `_` dropped.
fn headings(text: &str) -> BTreeSet<String> {
    text.lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| {
            l.trim_start_matches('#')
                .trim()
                .to_lowercase()
                .chars()
                .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
                .map(|c| if c == ' ' { '-' } else { c })
                .collect()
        })
        .collect()
}

/// The layers of `src/`, lowest first, as ARCHITECTURE.md lists them; a
/// module may name only modules before it in this list.
const LAYERS: &[&str] = &[
    "error", "memory", "mesh", "fem", "strain", "surface", "micro", "imaging", "gpu", "render",
    "export", "scenario", "pipeline", "bench", "viewer", "cli",
];

/// Every `crate::X` (or `crate::{X, …}`) path outside test code names a
/// layer below the file's own, and ARCHITECTURE.md states the same order.
#[test]
fn modules_import_only_lower_layers() {
    let arch = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let stated = LAYERS[..LAYERS.len() - 1]
        .iter()
        .map(|m| format!("`{m}`"))
        .collect::<Vec<_>>()
        .join(" → ");
    assert!(
        arch.split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
            .contains(&stated),
        "ARCHITECTURE.md states the layers as: {stated}"
    );
    let mut files = Vec::new();
    collect(&root().join("src"), &mut files);
    let src = root().join("src");
    let mut upward = Vec::new();
    for (path, text) in &files {
        let rel = Path::new(path).strip_prefix(&src).unwrap();
        let top = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let top = top.trim_end_matches(".rs");
        if top == "lib" || top == "main" {
            continue;
        }
        let level = LAYERS
            .iter()
            .position(|m| *m == top)
            .unwrap_or_else(|| panic!("src/{top} is in no layer of this test's table"));
        // Test modules may reach anywhere.
        let code = match text.find("#[cfg(test)]\nmod tests") {
            Some(i) => &text[..i],
            None => text,
        };
        for named in crate_paths(code) {
            let Some(other) = LAYERS.iter().position(|m| *m == named) else {
                continue;
            };
            if other > level {
                upward.push(format!("{} names crate::{named}", rel.display()));
            }
        }
    }
    assert!(upward.is_empty(), "imports of a higher layer: {upward:#?}");
}

/// The top-level modules `code` names through `crate::`.
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let word = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    for (i, _) in code.match_indices("crate::") {
        let after = &code[i + 7..];
        if let Some(group) = after.strip_prefix('{') {
            let inner = &group[..group.find('}').unwrap_or(group.len())];
            for item in inner.split(',') {
                out.insert(word(item.trim()));
            }
        } else {
            out.insert(word(after));
        }
    }
    out
}

/// ARCHITECTURE.md's shader table has a row for every file of `shaders/`,
/// and each row's module file and test exist.
#[test]
fn the_shader_table_covers_every_shader() {
    let arch = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let rows: Vec<Vec<String>> = arch
        .lines()
        .filter(|l| l.starts_with("| `") && l.contains(".wgsl`"))
        .map(|l| {
            l.trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_string())
                .collect()
        })
        .collect();
    let mut shaders: Vec<String> = std::fs::read_dir(root().join("shaders"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".wgsl"))
        .collect();
    shaders.sort();
    let mut listed: Vec<String> = rows
        .iter()
        .map(|r| r[0].trim_matches('`').to_string())
        .collect();
    listed.sort();
    assert_eq!(listed, shaders, "ARCHITECTURE.md's shader table");
    for row in &rows {
        // `gpu::raster` → src/gpu/raster.rs
        let module = row[1].split('`').nth(1).unwrap();
        let file = root().join("src").join(module.replace("::", "/") + ".rs");
        assert!(file.exists(), "{}: no {}", row[0], file.display());
        // `gpu::raster_matches_the_cpu_reference` → fn … in tests/main/gpu.rs
        let test = row[3].split('`').nth(1).unwrap();
        let (topic, name) = test.split_once("::").unwrap();
        let source = std::fs::read_to_string(root().join(format!("tests/main/{topic}.rs")))
            .unwrap_or_else(|e| panic!("{}: {topic}: {e}", row[0]));
        assert!(
            name == "*" || source.contains(&format!("fn {name}(")),
            "{}: no test {test}",
            row[0]
        );
    }
}
