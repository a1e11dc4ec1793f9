//! `echelon fleet certs`: a development certificate authority and one
//! certificate per fleet identity (`leader`, `collector`, `router`,
//! `operator` for `fleet stop`/`resume`, `robot-1` …, `base-1` …), for
//! the secure mode (Zenoh mutual TLS + access control by common name).
//!
//! Files: `ca.pem`, `ca-key.pem`, and for each identity `<id>.pem` (signed by
//! the CA, common name `echelon-<id>`, usable as TLS server and client) and
//! `<id>-key.pem`. Keys are ECDSA P-256. For development: keep `ca-key.pem`
//! off the robots, and use a real PKI in production.

use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};

use crate::FleetError;
use crate::net::{common_name, identity_files};

/// Options of `fleet certs`.
#[derive(Debug, Clone)]
pub struct CertOptions {
    /// Output directory.
    pub dir: PathBuf,
    /// Number of robot identities (`robot-1` … `robot-N`).
    pub robots: u32,
    /// Extra subject alternative names (host names or IP addresses the fleet's
    /// machines listen on); `localhost`, `127.0.0.1` and `::1` are always in.
    pub hosts: Vec<String>,
}

fn rc(e: rcgen::Error) -> FleetError {
    FleetError::Config(format!("certificate generation: {e}"))
}

fn write(path: &Path, text: &str) -> Result<(), FleetError> {
    std::fs::write(path, text).map_err(FleetError::io(path))
}

/// Writes the CA and every identity's certificate and key; returns the files.
/// Every certificate is valid from 1975 to 4096 (rcgen's default).
pub fn generate(opts: &CertOptions) -> Result<Vec<PathBuf>, FleetError> {
    generate_with(opts, &[])
}

/// [`generate`], each identity of `expires` (`(identity, days)`) with a
/// certificate that expires `days` days from now (negative: expired
/// already), valid from a day before that at the latest: rehearsals of
/// `fleet doctor`'s certificate findings (`fleet certs --expires ID=DAYS`).
pub fn generate_with(
    opts: &CertOptions,
    expires: &[(String, f64)],
) -> Result<Vec<PathBuf>, FleetError> {
    if let Some((id, days)) = expires.iter().find(|(_, d)| !d.is_finite()) {
        return Err(FleetError::Config(format!(
            "{id}: {days} days is not a number of days"
        )));
    }
    let ids = crate::net::identities(opts.robots);
    if let Some((id, _)) = expires.iter().find(|(e, _)| !ids.contains(e)) {
        return Err(FleetError::Config(format!(
            "no identity {id} in a fleet of {} robots",
            opts.robots
        )));
    }
    std::fs::create_dir_all(&opts.dir).map_err(FleetError::io(&opts.dir))?;
    let mut written = Vec::new();

    let ca_key = KeyPair::generate().map_err(rc)?;
    let mut ca_params = CertificateParams::new(Vec::<String>::new()).map_err(rc)?;
    ca_params
        .distinguished_name
        .push(DnType::CommonName, "echelon development CA");
    ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca_params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    let ca_cert = ca_params.self_signed(&ca_key).map_err(rc)?;
    let ca_path = opts.dir.join("ca.pem");
    let ca_key_path = opts.dir.join("ca-key.pem");
    write(&ca_path, &ca_cert.pem())?;
    write(&ca_key_path, &ca_key.serialize_pem())?;
    written.extend([ca_path, ca_key_path]);
    let issuer = Issuer::new(ca_params, ca_key);

    let mut sans = vec![
        "localhost".to_owned(),
        "127.0.0.1".to_owned(),
        "::1".to_owned(),
    ];
    sans.extend(opts.hosts.iter().cloned());
    for id in ids {
        let key = KeyPair::generate().map_err(rc)?;
        let mut params = CertificateParams::new(sans.clone()).map_err(rc)?;
        params
            .distinguished_name
            .push(DnType::CommonName, common_name(&id));
        params.key_usages = vec![
            KeyUsagePurpose::DigitalSignature,
            KeyUsagePurpose::KeyEncipherment,
        ];
        params.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        if let Some((_, days)) = expires.iter().find(|(e, _)| *e == id) {
            let until = time::OffsetDateTime::now_utc()
                + time::Duration::seconds_f64((days * 86_400.0).clamp(-1e11, 1e11));
            params.not_after = until;
            params.not_before = params.not_before.min(until - time::Duration::days(1));
        }
        let cert = params.signed_by(&key, &issuer).map_err(rc)?;
        let (cert_path, key_path) = identity_files(&opts.dir, &id);
        write(&cert_path, &cert.pem())?;
        write(&key_path, &key.serialize_pem())?;
        written.extend([cert_path, key_path]);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_ca_and_every_identity() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let files = generate(&CertOptions {
            dir: dir.path().to_path_buf(),
            robots: 2,
            hosts: vec!["robot1.local".into()],
        })
        .unwrap_or_else(|e| panic!("{e}"));
        // CA + leader, collector, router, operator, robot-1, robot-2, base-1,
        // base-2, each cert + key.
        assert_eq!(files.len(), 18);
        assert!(dir.path().join("operator.pem").is_file());
        let pem = std::fs::read_to_string(dir.path().join("robot-2.pem")).unwrap_or_default();
        assert!(pem.starts_with("-----BEGIN CERTIFICATE-----"));
        let key = std::fs::read_to_string(dir.path().join("robot-2-key.pem")).unwrap_or_default();
        assert!(key.contains("PRIVATE KEY"));
    }
}
