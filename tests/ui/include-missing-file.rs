mvad::hybrid!(include "models/no_such_model.hyb");

fn main() {}
