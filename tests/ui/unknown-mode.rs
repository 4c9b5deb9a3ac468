use mvad::hybrid;

hybrid! {
    model Thermostat {
        state temp = 19.0;
        mode heating { der(temp) = 1.0; event switch_off when temp >= 22 -> coolin; }
        mode cooling { der(temp) = -1.0; event switch_on when temp <= 18 -> heating; }
    }
}

fn main() {}
