"""The estimators' error models beside the navigation state: the DVL's correlated error, the water current, the
DVL's run-constant error, the weakly determined directions held, the noise levels taken from the data."""
