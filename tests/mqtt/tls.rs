//! TLS to the broker: a test CA, a client certificate, a wrong CA.

use super::*;

fn ca_params(name: &str) -> rcgen::CertificateParams {
    let mut ca = rcgen::CertificateParams::new(Vec::<String>::new()).expect("ca params");
    ca.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    ca.distinguished_name.push(rcgen::DnType::CommonName, format!("fme test CA {name}"));
    ca.key_usages = vec![rcgen::KeyUsagePurpose::KeyCertSign, rcgen::KeyUsagePurpose::CrlSign];
    ca
}

/// The key of the `broker` CA written by [`make_certs`].
fn ca_key_of(dir: &Path) -> rcgen::KeyPair {
    let pem = std::fs::read_to_string(dir.join("broker-ca.key")).expect("read CA key");
    rcgen::KeyPair::from_pem(&pem).expect("CA key")
}

/// A client certificate signed by the `broker` CA: (cert.pem, key.pem).
fn client_cert(dir: &Path, ca_key: &rcgen::KeyPair) -> (PathBuf, PathBuf) {
    let issuer = rcgen::Issuer::new(ca_params("broker"), ca_key);
    let mut p = rcgen::CertificateParams::new(Vec::<String>::new()).expect("params");
    p.distinguished_name.push(rcgen::DnType::CommonName, "box4");
    let key = rcgen::KeyPair::generate().expect("client key");
    let cert = p.signed_by(&key, &issuer).expect("client cert");
    let paths = (dir.join("client.pem"), dir.join("client.key"));
    std::fs::write(&paths.0, cert.pem()).expect("write");
    std::fs::write(&paths.1, key.serialize_pem()).expect("write");
    paths
}

/// A CA and a certificate for 127.0.0.1/localhost signed by it: (ca.pem, server.pem, server.key);
/// the CA's key is kept as `<name>-ca.key`.
fn make_certs(dir: &Path, name: &str) -> (PathBuf, PathBuf, PathBuf) {
    let ca_key = rcgen::KeyPair::generate().expect("ca key");
    std::fs::write(dir.join(format!("{name}-ca.key")), ca_key.serialize_pem()).expect("write");
    let ca = rcgen::CertifiedIssuer::self_signed(ca_params(name), ca_key).expect("ca cert");
    let server = rcgen::CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()]).expect("params");
    let key = rcgen::KeyPair::generate().expect("server key");
    let cert = server.signed_by(&key, &ca).expect("server cert");
    let paths = (dir.join(format!("{name}-ca.pem")), dir.join(format!("{name}.pem")), dir.join(format!("{name}.key")));
    std::fs::write(&paths.0, ca.pem()).expect("write");
    std::fs::write(&paths.1, cert.pem()).expect("write");
    std::fs::write(&paths.2, key.serialize_pem()).expect("write");
    (paths.0, paths.1, paths.2)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_with_a_test_ca_and_a_wrong_ca_is_a_telemetry_fault() {
    let certs = tempfile::tempdir().expect("tempdir");
    let (ca, cert, key) = make_certs(certs.path(), "broker");
    let (other_ca, _, _) = make_certs(certs.path(), "other");
    let (tls_port, mutual_port) = (free_port(), free_port());
    let broker = Broker::start(&format!(
        "listener {tls_port} 127.0.0.1\ncafile {0}\ncertfile {1}\nkeyfile {2}\n\
         listener {mutual_port} 127.0.0.1\ncafile {0}\ncertfile {1}\nkeyfile {2}\nrequire_certificate true\n",
        ca.display(),
        cert.display(),
        key.display()
    ));
    let sub = Sub::start(broker.port, "sub-tls", "t4/#", true);
    let seq = tempfile::tempdir().expect("tempdir");
    support::write_sequence(seq.path(), 40, 160, 96, 30);
    let mut cfg = daemon_config(seq.path(), tls_port, "t4", "box4");
    cfg.output.mqtt.tls = true;
    cfg.output.mqtt.ca_file = ca;
    let daemon = start_daemon(cfg.clone(), seq.path()).await;
    assert!(
        wait_for(Duration::from_secs(10), || sub.on("t4/box4/activity").len() >= 3).await,
        "activity over TLS: {:?} {:?}\n{}",
        sub.all(),
        daemon.shared().health().mqtt,
        broker.log()
    );
    check_all(&sub.all(), "t4", "box4");
    daemon.shutdown().await;

    // A listener that requires a client certificate: without one refused, with one (signed by
    // the broker's CA) connected.
    let (client_cert, client_key) = client_cert(certs.path(), &ca_key_of(certs.path()));
    let mut mutual = cfg.clone();
    mutual.output.mqtt.broker = format!("127.0.0.1:{mutual_port}");
    for (with_cert, want) in [(false, MqttLink::AuthFailed), (true, MqttLink::Connected)] {
        mutual.output.mqtt.box_id = format!("box4-cert-{with_cert}");
        if with_cert {
            mutual.output.mqtt.cert_file = client_cert.clone();
            mutual.output.mqtt.key_file = client_key.clone();
        }
        let shared = Arc::new(Shared::new(String::new(), 50));
        let (tx, _thread) = fme::output::mqtt::spawn(&mutual, shared.clone()).expect("spawn");
        assert!(
            wait_for(Duration::from_secs(5), || shared.health().mqtt.link == want).await,
            "client certificate {with_cert}: {:?}",
            shared.health().mqtt
        );
        drop(tx);
        shared.request_stop();
    }

    // A broker certificate from another CA: refused, counted as a telemetry fault, retried.
    cfg.output.mqtt.ca_file = other_ca;
    cfg.output.mqtt.box_id = "box4b".into();
    let shared = Arc::new(Shared::new(String::new(), 50));
    let (tx, _thread) = fme::output::mqtt::spawn(&cfg, shared.clone()).expect("spawn");
    assert!(
        wait_for(Duration::from_secs(5), || shared.health().mqtt.link == MqttLink::AuthFailed).await,
        "{:?}",
        shared.health().mqtt
    );
    assert!(shared.health().mqtt.last_error.contains("TLS"), "{:?}", shared.health().mqtt);
    drop(tx);
    shared.request_stop();
}
