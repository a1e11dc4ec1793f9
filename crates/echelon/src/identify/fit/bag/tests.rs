use super::*;

#[test]
fn the_step_rides_the_limit_then_lags() {
    // From 0 to 1 with τ = 0.1, a = 2: rides until the error is aτ = 0.2,
    // i.e. 0.4 s, then decays as the lag.
    let (x, ride) = step(0.0, 1.0, 0.3, 0.1, 0.5);
    assert!((x - 0.6).abs() < 1e-12 && (ride - 0.3).abs() < 1e-12);
    let (x, ride) = step(0.0, 1.0, 0.5, 0.1, 0.5);
    assert!((x - (1.0 - 0.2 * (-1.0_f64).exp())).abs() < 1e-12, "{x}");
    assert!((ride - 0.4).abs() < 1e-12);
    // Without a limit: the lag; without a lag: the command.
    let (x, _) = step(0.0, 1.0, 0.1, 0.1, 0.0);
    assert!((x - (1.0 - (-1.0_f64).exp())).abs() < 1e-12);
    assert_eq!(step(0.3, -1.0, 0.01, 0.0, 0.0).0, -1.0);
    // A pure rate limiter reaches the command and stays.
    let (x, ride) = step(0.0, -1.0, 1.0, 0.0, 0.5);
    assert!((x + 1.0).abs() < 1e-12 && (ride - 0.5).abs() < 1e-12);
}
