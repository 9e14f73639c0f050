"""The model and its theory: instances (i.i.d. or Markov hidden states), means, pseudo-rewards,
competitive arms, the theorems' bounds, and the channels that draw the hidden state."""
