"""The paper's method: the LSTM population, its training, the sparrow-search fusion, the streaming
front end and the DLSTM compensators."""
