"""The roller-chain dwell mechanism (El-Shakery 1991): chain path, dwell kinematics, multibody model."""
