"""The external Geneva drive: closed-form kinematics, the multibody model, the reduced reference."""
