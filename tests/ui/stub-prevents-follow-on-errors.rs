use mvad::hybrid;

hybrid! {
    model Ball {
        state h = 2.0;
        flow {
            der(h) = undefined_thing;
        }
    }
}

// The model has an error; using its name must not add "cannot find type `Ball`".
fn take(_: Ball, _: BallParams) {}

fn main() {
    let _ = take;
}
