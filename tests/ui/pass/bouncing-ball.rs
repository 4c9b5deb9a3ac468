//! The spec's first model, inline, with both comment styles and a doc comment.
use mvad::hybrid;

hybrid! {
    /// Bouncing ball: the seed paper's E1 (doc comments are skipped like comments).
    model BouncingBall {
        param e = 0.8;            // restitution coefficient, differentiable
        param g = 9.81;
        param h0 = 2.0;
        param v0 = 0.0;
        state h = h0;             /* initial values may depend on params */
        state v = v0;

        flow {
            der(h) = v;
            der(v) = -g;
        }

        event impact when h <= 0 {
            v = -e * v;
        }

        observe height = h;
        observe velocity = v;

        cost = integral(h);
        horizon 2.0;
    }
}

hybrid! {
    model Thermostat {
        param k = 0.5;  param lo = 18.0;  param hi = 22.0;  param p = 10.0;
        const ambient = 10.0;
        state temp = 19.0;
        initial mode heating;
        mode heating {
            der(temp) = -k * (temp - ambient) + p;
            event switch_off when temp >= hi -> cooling;
        }
        mode cooling {
            der(temp) = -k * (temp - ambient);
            event switch_on when temp <= lo -> heating;
        }
        cost = integral((temp - 20)^2);
        horizon 10;
    }
}

fn main() {
    let params = BouncingBallParams::default();
    assert_eq!(params.e, 0.8);
    assert_eq!(params.g, 9.81);
    let _ball = BouncingBall::new();
    let t = ThermostatParams::default();
    assert_eq!(t.hi, 22.0);
    let _thermostat = Thermostat::new();
}
