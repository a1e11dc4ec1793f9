//! The operator token: the secret a `fleet resume` proves it knows.
//!
//! A stop is always obeyed (stopping is never unsafe), but a resume sets
//! robots moving, so it is obeyed only when it carries a proof made with
//! the fleet's operator token ([`OperatorToken::sign`] over the command's
//! bytes, in `FleetCommand::proof`), in every mode. The token is 128 random
//! bits from the operating system, written as 32 lowercase hexadecimal
//! characters. `fleet up` makes one (or takes [`TOKEN_ENV`]), writes it to
//! `OUT/operator-token` ([`TOKEN_FILE`], mode 0600) and hands it to every
//! process it starts in [`TOKEN_ENV`]; a process started by hand reads it
//! from the same variable. The live dashboard's URL carries the same token.
//!
//! The proof is HMAC-SHA256 keyed by the token's 16 bytes over the
//! command's fields (everything but the proof; `FleetCommand::signed_bytes`
//! lays them out), in lowercase hexadecimal: whoever sees a resume on the
//! network learns nothing of the token and cannot make a resume of another
//! number, order, sender or reason.

use std::fmt;
use std::path::Path;

use ring::hmac;
use ring::rand::SecureRandom;

use crate::FleetError;

/// The environment variable a process reads its operator token from.
pub const TOKEN_ENV: &str = "ECHELON_OPERATOR_TOKEN";
/// The file `fleet up` writes the token to, in its output directory.
pub const TOKEN_FILE: &str = "operator-token";
/// The length of a token written out, hexadecimal characters.
pub const TOKEN_HEX_LEN: usize = 32;
/// The length of a proof, hexadecimal characters (HMAC-SHA256).
pub const PROOF_HEX_LEN: usize = 64;
/// The fleet's operator token (its `Debug` does not show it).
#[derive(Clone)]
pub struct OperatorToken([u8; TOKEN_HEX_LEN / 2]);

impl fmt::Debug for OperatorToken {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("OperatorToken(…)")
    }
}

impl PartialEq for OperatorToken {
    /// In time independent of where they differ.
    fn eq(&self, other: &OperatorToken) -> bool {
        self.0
            .iter()
            .zip(other.0.iter())
            .fold(0u8, |d, (a, b)| d | (a ^ b))
            == 0
    }
}

impl Eq for OperatorToken {}

/// `bytes` in lowercase hexadecimal.
fn hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(2 * bytes.len());
    for b in bytes {
        s.push(char::from(DIGITS[usize::from(b >> 4)]));
        s.push(char::from(DIGITS[usize::from(b & 0x0f)]));
    }
    s
}

/// The bytes of hexadecimal `s` (either case), `None` if it is not an
/// even number of hexadecimal digits.
fn unhex(s: &str) -> Option<Vec<u8>> {
    let digit = |c: u8| char::from(c).to_digit(16).map(|d| d as u8);
    let s = s.as_bytes();
    if !s.len().is_multiple_of(2) {
        return None;
    }
    s.chunks(2)
        .map(|p| Some((digit(p[0])? << 4) | digit(p[1])?))
        .collect()
}

impl OperatorToken {
    /// A new token: 128 bits from the operating system's random source.
    pub fn random() -> Result<OperatorToken, FleetError> {
        let mut bytes = [0u8; TOKEN_HEX_LEN / 2];
        ring::rand::SystemRandom::new()
            .fill(&mut bytes)
            .map_err(|_| FleetError::Config("no random bytes from the system".into()))?;
        Ok(OperatorToken(bytes))
    }

    /// A token from its text: exactly 32 hexadecimal characters.
    pub fn parse(s: &str) -> Result<OperatorToken, FleetError> {
        let bad = || {
            FleetError::Config(format!(
                "an operator token is {TOKEN_HEX_LEN} hexadecimal characters (as `fleet up` writes to OUT/{TOKEN_FILE}); got {} characters{}",
                s.chars().count(),
                if s.chars().all(|c| c.is_ascii_hexdigit()) {
                    ""
                } else {
                    ", not all hexadecimal"
                }
            ))
        };
        if s.len() != TOKEN_HEX_LEN {
            return Err(bad());
        }
        let bytes = unhex(s).ok_or_else(bad)?;
        let mut token = [0u8; TOKEN_HEX_LEN / 2];
        token.copy_from_slice(&bytes);
        Ok(OperatorToken(token))
    }

    /// The token in [`TOKEN_ENV`] (`None`: not set, or empty); an error
    /// naming the variable if it is not a token.
    pub fn from_env() -> Result<Option<OperatorToken>, FleetError> {
        match std::env::var(TOKEN_ENV) {
            Ok(s) if s.trim().is_empty() => Ok(None),
            Ok(s) => OperatorToken::parse(s.trim())
                .map(Some)
                .map_err(|e| FleetError::Config(format!("{TOKEN_ENV}: {e}"))),
            Err(std::env::VarError::NotPresent) => Ok(None),
            Err(std::env::VarError::NotUnicode(_)) => Err(FleetError::Config(format!(
                "{TOKEN_ENV}: not an operator token (not UTF-8)"
            ))),
        }
    }

    /// The token in file `path` (as [`OperatorToken::write_file`] writes
    /// it; surrounding white space ignored).
    pub fn from_file(path: &Path) -> Result<OperatorToken, FleetError> {
        let text = std::fs::read_to_string(path).map_err(FleetError::io(path))?;
        OperatorToken::parse(text.trim())
            .map_err(|e| FleetError::Config(format!("{}: {e}", path.display())))
    }

    /// Writes the token to `path` with a final newline, readable by its
    /// owner only (mode 0600, also when the file was there).
    pub fn write_file(&self, path: &Path) -> Result<(), FleetError> {
        use std::io::Write;
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create(true).truncate(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
            options.mode(0o600);
            // An older file keeps its mode through `open`: set it first.
            if path.exists() {
                std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600))
                    .map_err(FleetError::io(path))?;
            }
        }
        let mut file = options.open(path).map_err(FleetError::io(path))?;
        writeln!(file, "{}", self.to_hex()).map_err(FleetError::io(path))
    }

    /// The token as text: 32 lowercase hexadecimal characters (what
    /// [`OperatorToken::parse`] reads).
    pub fn to_hex(&self) -> String {
        hex(&self.0)
    }

    fn key(&self) -> hmac::Key {
        hmac::Key::new(hmac::HMAC_SHA256, &self.0)
    }

    /// The proof of `bytes` made with this token: HMAC-SHA256, 64
    /// lowercase hexadecimal characters.
    pub fn sign(&self, bytes: &[u8]) -> String {
        hex(hmac::sign(&self.key(), bytes).as_ref())
    }

    /// Whether `proof` is this token's proof of `bytes` (compared in
    /// constant time).
    pub fn verify(&self, bytes: &[u8], proof: &str) -> bool {
        if proof.len() != PROOF_HEX_LEN {
            return false;
        }
        let Some(tag) = unhex(proof) else {
            return false;
        };
        hmac::verify(&self.key(), bytes, &tag).is_ok()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use proptest::prelude::*;

    use super::*;

    #[test]
    fn a_random_token_is_32_lowercase_hex_digits_and_parses_back() {
        let t = OperatorToken::random().unwrap();
        let text = t.to_hex();
        assert_eq!(text.len(), TOKEN_HEX_LEN);
        assert!(text.chars().all(|c| matches!(c, '0'..='9' | 'a'..='f')));
        assert_eq!(OperatorToken::parse(&text).unwrap(), t);
        assert_ne!(OperatorToken::random().unwrap(), t);
        assert_eq!(format!("{t:?}"), "OperatorToken(…)");
        // Upper case is the same token.
        assert_eq!(OperatorToken::parse(&text.to_uppercase()).unwrap(), t);
    }

    #[test]
    fn parse_refuses_what_is_not_a_token() {
        for bad in [
            "",
            "abc",
            "0123456789abcdef0123456789abcde",
            "0123456789abcdef0123456789abcdef0",
            "0123456789abcdef0123456789abcdeg",
            " 0123456789abcdef0123456789abcde",
            "0123456789abcdef0123456789abcdé",
            "+123456789abcdef0123456789abcdef",
        ] {
            let e = OperatorToken::parse(bad).unwrap_err().to_string();
            assert!(e.contains("32 hexadecimal characters"), "{bad}: {e}");
        }
    }

    #[test]
    fn the_token_file_is_the_owners_only_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(TOKEN_FILE);
        std::fs::write(&path, "old").unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        }
        let t = OperatorToken::random().unwrap();
        t.write_file(&path).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            format!("{}\n", t.to_hex())
        );
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        assert_eq!(OperatorToken::from_file(&path).unwrap(), t);
        std::fs::write(&path, "not a token\n").unwrap();
        let e = OperatorToken::from_file(&path).unwrap_err().to_string();
        assert!(e.contains(TOKEN_FILE) && e.contains("hexadecimal"), "{e}");
        assert!(OperatorToken::from_file(&dir.path().join("none")).is_err());
    }

    proptest! {
        /// Anything but 32 hexadecimal characters is refused.
        #[test]
        fn parse_takes_exactly_32_hex_digits(s in "\\PC{0,40}") {
            let ok = s.len() == TOKEN_HEX_LEN && s.chars().all(|c| c.is_ascii_hexdigit());
            prop_assert_eq!(OperatorToken::parse(&s).is_ok(), ok);
        }
    }
}
