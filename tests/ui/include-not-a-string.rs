mvad::hybrid!(include models::ball);

fn main() {}
