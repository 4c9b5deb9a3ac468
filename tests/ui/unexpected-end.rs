use mvad::hybrid;

hybrid! {
    model Ball
}

fn main() {}
