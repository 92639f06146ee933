//! The README as a guide: at most 250 lines, every file it and the docs link to exists, and every
//! command of its shell blocks is one that CI runs (`scripts/ci/readme_commands.py` runs the
//! calsim commands with the release binary; the others must be lines of `.ci/run`).

mod common;

use std::path::Path;

fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        let end = rest.find(')').unwrap_or(rest.len());
        out.push(rest[..end].to_string());
    }
    out
}

#[test]
fn the_readme_has_at_most_250_lines() {
    let text = std::fs::read_to_string(common::repo().join("README.md")).expect("README.md");
    let lines = text.lines().count();
    assert!(lines <= 250, "README.md has {lines} lines");
}

#[test]
fn every_file_the_readme_and_the_docs_link_to_exists() {
    let repo = common::repo();
    let mut pages = vec![repo.join("README.md"), repo.join("results/README.md"), repo.join("python/README.md")];
    for entry in std::fs::read_dir(repo.join("docs")).expect("docs/") {
        let p = entry.expect("an entry").path();
        if p.extension().is_some_and(|e| e == "md") {
            pages.push(p);
        }
    }
    for page in pages {
        let text = std::fs::read_to_string(&page).expect("a page");
        let dir = page.parent().unwrap_or(Path::new("."));
        for link in links(&text) {
            if link.starts_with("http") || link.starts_with('#') || link.is_empty() {
                continue;
            }
            let file = link.split('#').next().unwrap_or_default();
            assert!(dir.join(file).exists(), "{}: link to {link}: no such file", page.display());
        }
    }
}

#[test]
fn every_shell_command_of_the_readme_is_one_ci_runs() {
    let repo = common::repo();
    let readme = std::fs::read_to_string(repo.join("README.md")).expect("README.md");
    let ci = std::fs::read_to_string(repo.join(".ci/run")).expect(".ci/run");
    assert!(ci.contains("scripts/ci/readme_commands.py"), ".ci/run does not run the README's commands");
    let script = std::fs::read_to_string(repo.join("scripts/ci/readme_commands.py")).expect("the script");
    let mut count = 0;
    for block in readme.split("```sh\n").skip(1) {
        let block = block.split("```").next().unwrap_or_default();
        for line in block.lines() {
            let line = line.split("  #").next().unwrap_or_default().trim();
            if line.is_empty() {
                continue;
            }
            count += 1;
            let calsim = line.starts_with("calsim ") || line.starts_with("cargo run --release -- ");
            assert!(
                calsim || script.contains(&format!("{line:?}")) || script.contains(&format!("'{line}'")),
                "README: {line:?} is run by no CI step"
            );
        }
    }
    assert!(count >= 10, "the README shows {count} commands");
}
