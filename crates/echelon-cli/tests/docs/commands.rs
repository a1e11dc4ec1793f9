//! Every `echelon …` command line written in README.md and docs/*.md, in
//! code blocks and in inline code, checked against the real CLI: the binary
//! parses it (`ECHELON_PARSE_ONLY`: clap only, nothing runs) and the error,
//! if any, is judged.
//!
//! A line is read as a shell reads it (quotes, `\` continuations, a `$ `
//! prompt, `cargo run [--release] -- …` for `echelon …`, `VAR=value`
//! before it; a comment, a pipe, `&`, `&&`, `;` or a redirection ends it)
//! and as a usage line (`[optional]`, `(a | b)`, `a|b` values, `<NAME |
//! FILE>` and upper-case placeholders, `…`). A usage line is checked as
//! several command lines: its required part alone, then with each
//! optional group (and its enclosing ones), then with each other
//! alternative, so that every flag written is parsed at least once and
//! two groups the doc offers as alternatives are never combined.
//!
//! Failures: a subcommand or flag the binary does not have, a flag without
//! its value, a positional too many, flags that conflict, a value the
//! binary refuses that is not a placeholder. A placeholder value the
//! binary refuses (`--agent K`) is replaced by plausible values until one
//! is accepted, so the flags after it are checked too. A missing required
//! argument is accepted in inline code and usage lines (they name a
//! command, not all of it), not in a shell code block, which one runs as
//! written.
//!
//! `DOCS_DEBUG=1 cargo test -p echelon-cli --test docs` prints every
//! command line checked, as the binary is given it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One `echelon …` command found in a doc.
#[derive(Debug, Clone)]
pub(crate) struct DocLine {
    /// `docs/fleet.md:12`.
    pub(crate) at: String,
    /// The command as written (continuations joined).
    pub(crate) text: String,
    /// From a shell code block (or after a `$ ` prompt): run as written.
    pub(crate) literal: bool,
}

/// README.md and docs/*.md, in order.
pub(crate) fn doc_files(root: &Path) -> Vec<PathBuf> {
    let mut files = vec![root.join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

/// The command of one shell line, as `echelon ARGS…` (`None`: not one):
/// a `$ ` prompt, `VAR=value` assignments and `ExecStart=` dropped,
/// `cargo run [--release] … -- ARGS` and `…/echelon ARGS` read as
/// `echelon ARGS`.
pub(crate) fn command_of(line: &str) -> Option<String> {
    let mut s = line.trim_start();
    s = s.strip_prefix("$ ").unwrap_or(s).trim_start();
    s = s.strip_prefix("ExecStart=").unwrap_or(s);
    // Environment assignments before the command.
    loop {
        let word = s.split_whitespace().next()?;
        let Some((name, _)) = word.split_once('=') else {
            break;
        };
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_uppercase() || c == '_') {
            break;
        }
        s = s[word.len()..].trim_start();
    }
    if let Some(rest) = s.strip_prefix("cargo run") {
        let (_, args) = rest.split_once(" -- ")?;
        return Some(format!("echelon {}", args.trim_start()));
    }
    let word = s.split_whitespace().next()?;
    let name = word.rsplit('/').next()?;
    let rest = s[word.len()..].trim_start();
    // `echelon` then a subcommand (a lower-case word), or nothing.
    (name == "echelon"
        && rest
            .chars()
            .next()
            .is_none_or(|c| c.is_ascii_lowercase() || c == '-'))
    .then(|| format!("echelon {rest}").trim_end().to_owned())
}

/// The inline code spans of a Markdown line (any number of backticks).
fn inline_code(line: &str) -> Vec<String> {
    let mut spans = Vec::new();
    let b = line.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'`' {
            i += 1;
            continue;
        }
        let n = b[i..].iter().take_while(|&&c| c == b'`').count();
        let open = &line[i..i + n];
        let start = i + n;
        let mut j = start;
        let mut end = None;
        while let Some(k) = line[j..].find(open) {
            let at = j + k;
            let run = b[at..].iter().take_while(|&&c| c == b'`').count();
            if run == n {
                end = Some(at);
                break;
            }
            j = at + run;
        }
        match end {
            Some(e) => {
                spans.push(line[start..e].trim().to_owned());
                i = e + n;
            }
            None => i = start,
        }
    }
    spans
}

/// Every `echelon …` command of a Markdown text: code block lines (a `\`
/// continuation joined) and inline code (`\|` in a table read as `|`;
/// `fleet SUBCOMMAND …` read as `echelon fleet SUBCOMMAND …`).
pub(crate) fn command_lines(name: &str, text: &str) -> Vec<DocLine> {
    let mut found = Vec::new();
    let mut fence: Option<String> = None;
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        let n = i + 1;
        i += 1;
        let trimmed = line.trim_start();
        if trimmed.starts_with("```") || trimmed.starts_with("~~~") {
            fence = match fence {
                Some(_) => None,
                None => Some(trimmed[3..].trim().to_owned()),
            };
            continue;
        }
        match &fence {
            Some(lang) => {
                let mut joined = line.to_owned();
                while joined.trim_end().ends_with('\\') && i < lines.len() {
                    let cut = joined.trim_end().len() - 1;
                    joined.truncate(cut);
                    joined.push(' ');
                    joined.push_str(lines[i].trim_start());
                    i += 1;
                }
                if let Some(command) = command_of(&joined) {
                    let shell =
                        matches!(lang.as_str(), "sh" | "bash" | "shell" | "console" | "zsh");
                    found.push(DocLine {
                        at: format!("{name}:{n}"),
                        text: command,
                        literal: shell || joined.trim_start().starts_with("$ "),
                    });
                }
            }
            None => {
                for span in inline_code(line) {
                    let span = span.replace("\\|", "|");
                    // `fleet up --ros2` in prose: `echelon fleet up --ros2`.
                    let span = match span.strip_prefix("fleet ") {
                        Some(rest) if rest.starts_with(|c: char| c.is_ascii_lowercase()) => {
                            format!("echelon {span}")
                        }
                        _ => span,
                    };
                    if let Some(command) = command_of(&span) {
                        found.push(DocLine {
                            at: format!("{name}:{n}"),
                            text: command,
                            literal: false,
                        });
                    }
                }
            }
        }
    }
    found
}

/// A token of a command line.
#[derive(Debug, Clone, PartialEq)]
enum Tok {
    /// A word; whether it is a placeholder; whether it was quoted.
    Word(String, bool, bool),
    /// `[` or `(`.
    Open(char),
    /// `]` or `)`.
    Close,
    /// `|` inside brackets: alternatives.
    Alt,
}

/// Whether a word stands for a value (`K`, `DIR`, `<NAME | FILE>`, `…`,
/// `$VAR`, `START:LEN`): no lower-case letter and an upper-case one, or
/// `<…>`, `…`, `$`.
pub(crate) fn is_placeholder(w: &str) -> bool {
    w.starts_with('<')
        || w.starts_with('$')
        || w.contains('…')
        || w.contains("...")
        || (!w.chars().any(|c| c.is_lowercase()) && w.chars().any(|c| c.is_uppercase()))
}

/// The tokens of a command, up to a comment, a pipe, `&`, `;` or the end;
/// redirections dropped.
fn tokenize(s: &str) -> Vec<Tok> {
    let c: Vec<char> = s.chars().collect();
    let mut toks = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < c.len() {
        if c[i].is_whitespace() {
            i += 1;
            continue;
        }
        match c[i] {
            '#' | '&' | ';' => break,
            '|' if depth == 0 => break,
            '|' => {
                toks.push(Tok::Alt);
                i += 1;
                continue;
            }
            '[' | '(' => {
                toks.push(Tok::Open(c[i]));
                depth += 1;
                i += 1;
                continue;
            }
            ']' | ')' => {
                toks.push(Tok::Close);
                depth = depth.saturating_sub(1);
                i += 1;
                continue;
            }
            '<' if c.get(i + 1).is_some_and(|n| n.is_alphanumeric()) => {
                let end = c[i..]
                    .iter()
                    .position(|&x| x == '>')
                    .map_or(c.len(), |p| i + p + 1);
                toks.push(Tok::Word(c[i..end].iter().collect(), true, false));
                i = end;
                continue;
            }
            _ => {}
        }
        // A redirection: `>`, `>>`, `2>`, `2>&1`, `&>`, `<`, with its target.
        let rest: String = c[i..].iter().collect();
        let redirect = ["2>&1", "&>", ">>", "2>", ">", "<"]
            .into_iter()
            .find(|r| rest.starts_with(r));
        if let Some(r) = redirect {
            i += r.chars().count();
            if r != "2>&1" {
                while i < c.len() && c[i].is_whitespace() {
                    i += 1;
                }
                while i < c.len() && !c[i].is_whitespace() {
                    i += 1;
                }
            }
            continue;
        }
        let mut word = String::new();
        let mut quoted = false;
        while i < c.len() && !c[i].is_whitespace() {
            match c[i] {
                q @ ('\'' | '"') => {
                    quoted = true;
                    i += 1;
                    while i < c.len() && c[i] != q {
                        word.push(c[i]);
                        i += 1;
                    }
                    i += 1;
                }
                '\\' if i + 1 < c.len() => {
                    word.push(c[i + 1]);
                    i += 2;
                }
                ']' | ')' if depth > 0 => break,
                ch => {
                    word.push(ch);
                    i += 1;
                }
            }
        }
        let placeholder = !quoted && is_placeholder(&word);
        toks.push(Tok::Word(word, placeholder, quoted));
    }
    toks
}

/// Whether `text` is written as a usage line (`[optional]`, `(a | b)`,
/// `<NAME>`, `…`) rather than a command to run as it is.
fn is_usage(text: &str) -> bool {
    tokenize(text).iter().any(|t| match t {
        Tok::Word(w, _, quoted) => !quoted && (w.starts_with('<') || w.contains('…')),
        _ => true,
    })
}

/// A node of a usage line.
#[derive(Debug, Clone)]
enum Node {
    /// A word: its alternatives (`paper|complete`), whether a placeholder.
    Word(usize, Vec<String>, bool),
    /// `[…]`: optional, its alternatives.
    Opt(usize, Vec<Vec<Node>>),
    /// `(…)`: one of its alternatives.
    Group(usize, Vec<Vec<Node>>),
}

/// Parses tokens into alternatives of sequences, up to a `Close` or the end.
fn parse(toks: &[Tok], i: &mut usize, next_id: &mut usize) -> Vec<Vec<Node>> {
    let mut alts = vec![Vec::new()];
    while *i < toks.len() {
        let t = toks[*i].clone();
        *i += 1;
        match t {
            Tok::Close => break,
            Tok::Alt => alts.push(Vec::new()),
            Tok::Open(kind) => {
                let id = *next_id;
                *next_id += 1;
                let inner = parse(toks, i, next_id);
                alts.last_mut().unwrap().push(if kind == '[' {
                    Node::Opt(id, inner)
                } else {
                    Node::Group(id, inner)
                });
            }
            Tok::Word(w, placeholder, quoted) => {
                let id = *next_id;
                *next_id += 1;
                let choices = if placeholder || quoted || !w.contains('|') {
                    vec![w]
                } else {
                    w.split('|').map(str::to_owned).collect()
                };
                alts.last_mut()
                    .unwrap()
                    .push(Node::Word(id, choices, placeholder));
            }
        }
    }
    alts
}

/// Which optional groups are in and which alternative each choice takes.
#[derive(Debug, Clone, Default, PartialEq, Eq, PartialOrd, Ord)]
struct Variant {
    included: BTreeSet<usize>,
    choice: BTreeMap<usize, usize>,
}

/// The variants worth parsing (see the module's doc): collected while
/// walking `seq`, `opts` the optional groups around it.
fn variants_of(seq: &[Node], opts: &[usize], out: &mut BTreeSet<Variant>) {
    for node in seq {
        let (id, alts, is_opt) = match node {
            Node::Word(id, choices, _) => {
                for k in 1..choices.len() {
                    out.insert(Variant {
                        included: opts.iter().copied().collect(),
                        choice: BTreeMap::from([(*id, k)]),
                    });
                }
                continue;
            }
            Node::Opt(id, alts) => (*id, alts, true),
            Node::Group(id, alts) => (*id, alts, false),
        };
        let mut inner: Vec<usize> = opts.to_vec();
        if is_opt {
            inner.push(id);
            out.insert(Variant {
                included: inner.iter().copied().collect(),
                choice: BTreeMap::new(),
            });
        }
        for (k, alt) in alts.iter().enumerate() {
            if k > 0 {
                out.insert(Variant {
                    included: inner.iter().copied().collect(),
                    choice: BTreeMap::from([(id, k)]),
                });
            }
            variants_of(alt, &inner, out);
        }
    }
}

/// The words of `seq` in variant `v`, each with whether it is a placeholder.
fn render(seq: &[Node], v: &Variant, out: &mut Vec<(String, bool)>) {
    for node in seq {
        match node {
            Node::Word(id, choices, placeholder) => {
                let k = v.choice.get(id).copied().unwrap_or(0);
                out.push((choices[k].clone(), *placeholder));
            }
            Node::Opt(id, alts) | Node::Group(id, alts) => {
                if matches!(node, Node::Opt(..)) && !v.included.contains(id) {
                    continue;
                }
                let k = v.choice.get(id).copied().unwrap_or(0);
                render(&alts[k], v, out);
            }
        }
    }
}

/// The command lines (argv after `echelon`, each word with whether it is a
/// placeholder) that `text` (`echelon …`) stands for.
pub(crate) fn expand(text: &str) -> Vec<Vec<(String, bool)>> {
    let toks = tokenize(text);
    let mut next_id = 0;
    let mut i = 0;
    let alts = parse(&toks, &mut i, &mut next_id);
    let seq = &alts[0];
    let mut set = BTreeSet::from([Variant::default()]);
    variants_of(seq, &[], &mut set);
    let mut lines: Vec<Vec<(String, bool)>> = Vec::new();
    for v in set {
        let mut words = Vec::new();
        render(seq, &v, &mut words);
        if words.first().is_some_and(|(w, _)| w == "echelon") {
            words.remove(0);
        }
        if !lines.contains(&words) {
            lines.push(words);
        }
    }
    lines
}

/// Values tried in turn for a placeholder the binary refuses.
const CANDIDATES: [&str; 11] = [
    "1",
    "0.5",
    "2",
    "1:1",
    "tcp/127.0.0.1:7447",
    "127.0.0.1:8765",
    "2:BUMP@1+1",
    "BUMP@1+1",
    "robot/1",
    "0123456789abcdef0123456789abcdef",
    "x",
];

/// Parses `args` with the binary in parse-only mode: `None` if it parses,
/// else clap's error kind and message.
fn parse_only(args: &[String]) -> Option<(String, String)> {
    let out = Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(args)
        .env("ECHELON_PARSE_ONLY", "1")
        .output()
        .unwrap();
    if out.status.success() {
        return None;
    }
    let err = String::from_utf8_lossy(&out.stderr).trim().to_owned();
    let (kind, message) = err.split_once(": ").unwrap_or(("?", &err));
    Some((kind.to_owned(), message.to_owned()))
}

/// The value clap refused in `message` and the argument it was for
/// (`invalid value 'K' for '--agent <K>'`: `K`, `--agent`; a positional's:
/// `<SCENARIO>`).
fn refused_value(message: &str) -> Option<(&str, &str)> {
    let rest = message.split_once("invalid value '")?.1;
    let (value, rest) = rest.split_once("' for '")?;
    let arg = rest.split(['\'', ' ']).next()?;
    Some((value, arg))
}

/// Checks one command line (`words` after `echelon`); `Err` says why it is
/// wrong. `literal`: from a shell code block, so it must be complete.
pub(crate) fn check(words: &[(String, bool)], literal: bool) -> Result<(), String> {
    let mut args: Vec<String> = words.iter().map(|(w, _)| w.clone()).collect();
    let placeholders: Vec<bool> = words.iter().map(|(_, p)| *p).collect();
    // Per argument position, the next candidate to try.
    let mut tried: BTreeMap<usize, usize> = BTreeMap::new();
    for _ in 0..64 {
        let Some((kind, message)) = parse_only(&args) else {
            return Ok(());
        };
        match kind.as_str() {
            "ValueValidation" | "InvalidValue" if !message.contains("a value is required") => {
                let (value, arg) = refused_value(&message).unwrap_or_default();
                // The position of the refused value (after its flag, for a
                // flag's): a placeholder, or one already replaced.
                let at = (0..args.len()).find(|&i| {
                    args[i] == value
                        && (!arg.starts_with('-') || i > 0 && args[i - 1] == arg)
                        && (placeholders[i] || tried.contains_key(&i))
                });
                let Some(at) = at else {
                    return Err(message);
                };
                let next = tried.entry(at).or_insert(0);
                let Some(candidate) = CANDIDATES.get(*next) else {
                    return Err(format!("no plausible value for {}: {message}", words[at].0));
                };
                *next += 1;
                args[at] = (*candidate).to_owned();
            }
            "MissingRequiredArgument" if !literal => return Ok(()),
            "DisplayHelpOnMissingArgumentOrSubcommand" | "MissingSubcommand"
                if !literal && !args.iter().any(|a| a.starts_with('-')) =>
            {
                return Ok(());
            }
            _ => return Err(format!("{kind}: {message}")),
        }
    }
    Err(format!(
        "no plausible values for the placeholders of {args:?}"
    ))
}

/// Every command line of every doc under `root` that is wrong, one line
/// each: where, the line, the command parsed, why.
pub(crate) fn wrong_lines(root: &Path) -> (usize, Vec<String>) {
    let mut checked = 0;
    let mut wrong = Vec::new();
    for path in doc_files(root) {
        let name = path.strip_prefix(root).unwrap().display().to_string();
        let text = std::fs::read_to_string(&path).unwrap();
        for line in command_lines(&name, &text) {
            let literal = line.literal && !is_usage(&line.text);
            for words in expand(&line.text) {
                checked += 1;
                if std::env::var_os("DOCS_DEBUG").is_some() {
                    eprintln!("{} {literal} {:?}", line.at, words);
                }
                if let Err(why) = check(&words, literal) {
                    let argv: Vec<&str> = words.iter().map(|(w, _)| w.as_str()).collect();
                    wrong.push(format!(
                        "{}: `{}` (as `echelon {}`): {why}",
                        line.at,
                        line.text,
                        argv.join(" ")
                    ));
                }
            }
        }
    }
    (checked, wrong)
}
