"""The 4-bar with a rolling pair next to the ground (Kar & Sen 2023): kinematics, atlas, model, reference."""
