use mvad::hybrid;

hybrid! {
    model Empty {
        param k = 0.5;
        flow {
        }
    }
}

fn main() {}
